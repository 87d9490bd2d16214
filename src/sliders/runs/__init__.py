"""The runs layer: how simulations are scheduled, stored and resumed.

* ``command``: the shape every run command shares (parser pieces, agreement
  rounds over the ranks, inputs read by rank 0, claims, ``RunPlan``, one-line errors);
* ``scheduler``: rows served over the ranks, stopped on a signal, reported;
* ``writes``: every row written checked (room on the disk, HDF5's late failures);
* ``signals``: how SIGINT and SIGTERM stop a command (``StopFlag`` and friends);
* ``rows``: one realisation of a scene as a row of a file;
* ``ensemble``: MPI (or serial) ensembles of disorder realisations into one HDF5 file;
* ``study``: parameter studies; ``prior``: prior ensembles (material drawn per row; the
  prior file: ``prior_spec``);
* ``merge``: chunk files of one ensemble merged into one;
* ``forecast``: the forecasting commands (a package, one module per subcommand);
* ``reproduction``: the paper's experiments run and judged, REPRODUCTION.md written;
* ``parallel``: optional MPI, the serial stand-in, aborts;
* ``cli``: the scene's command-line options shared by every command.

The top layer: may import every layer below (tests/test_layers.py).
"""
