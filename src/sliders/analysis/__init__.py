"""The analysis layer: what is computed from runs and files, never how they are run.

* ``observables``: per-realisation statistics and their ensemble averages;
* ``model``: the paper's analytical single slider and master equations;
* ``summary``: ensemble files read back and averaged;
* ``precursors``: the paper's measures of a set of runs (bursts, synchronisation, extremities);
* ``reproduction``: every statement of the paper judged (REPRODUCTION.md);
* ``study_spec`` and ``study_analysis``: a parameter study's design and its analysis.

Imports the simulation core and ``io`` only (tests/test_layers.py).
"""
