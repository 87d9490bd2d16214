"""The engine: what advances a chain from event to event, above the scene.

* ``contract``: what both backends implement (the chunk, the per-event
  schema, the packed kernel parameters, the merge of chunks);
* ``reference``: the NumPy reference (the executable specification);
* ``fortran_engine``: the compiled kernel (``fortran/``) behind the same API.

The physics of the scene's friction law and loading lives with the parts
(``sliders.parts``), which the engine calls with the scene's values.
"""
