"""The engine: what advances a chain from event to event.

* ``contract``: what both backends implement (the chunk, the per-event
  schema, the packed kernel parameters, the merge of chunks);
* ``loading``: how the drive parameter enters the forces and thresholds, and
  the next critical value in closed form (the tilt);
* ``friction``: static threshold, kinetic force and the draw at a stop;
* ``reference``: the NumPy reference (the executable specification);
* ``fortran_engine``: the compiled kernel (``fortran/``) behind the same API.
"""
