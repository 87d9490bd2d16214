"""Files: everything sliders reads or writes, and how it is kept trustworthy.

No other module of the package touches HDF5 (tests/test_io_layout.py checks it).

* ``run_file``: the single-run file (layout, writer, reader, whole-file
  checksum); ``Result.save``/``load`` call it;
* ``storage``: the ensemble file (layout, serial / gather / MPI-IO writers,
  readers of its header and rows, the summary of its done rows);
* ``study_file``: the study file (one ensemble layout per point, its writers,
  readers and the view xarray opens);
* ``prior_file``: the prior-ensemble file (rows drawn from a prior with their
  event catalogues, in row order) and its readers; ``catalogue``: catalogues
  in memory;
* ``h5tools``: the HDF5 helpers the file modules share (opening for reading,
  done rows and their checksums, dimension scales, virtual views);
* ``formats``: the format names, and the probe that tells a user what a
  path holds;
* ``conventions``: the xarray/CF conventions the files follow (dimension
  scales, units, descriptions, provenance);
* ``safeio``: atomic publication, CRC32 checksums of datasets and
  attributes, OS error messages;
* ``filelock``: the claim an output path is written under.
"""
