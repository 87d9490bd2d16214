"""The runs layer: how simulations are scheduled, stored and resumed.

* ``ensemble``: MPI (or serial) ensembles of disorder realisations into one HDF5 file;
* ``study``: parameter studies through the same scheduler;
* ``merge``: chunk files of one ensemble merged into one;
* ``parallel``: optional MPI, the serial stand-in, aborts;
* ``cli``: the scene's command-line options shared by every command.

The top layer: may import every layer below (tests/test_layers.py).
"""
