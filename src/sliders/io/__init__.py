"""Files: everything sliders reads or writes, and how it is kept trustworthy.

* ``storage``: the ensemble file (layout, serial / gather / MPI-IO writers,
  readers of its header and rows);
* ``conventions``: the xarray/CF conventions both files follow (dimension
  scales, units, descriptions);
* ``safeio``: atomic publication, CRC32 checksums of datasets and
  attributes, OS error messages;
* ``filelock``: the claim an output path is written under.

The single-run file is ``TiltResult.save``/``load`` (``sliders.result``).
"""
