"""Forecasting: the layer below the commands that forecasts a measured pile and infers its material.

* ``predict``: ``load_model`` reads a model file once; ``ForecastModel``, the model ``load()``
  gives, forecasts a catalogue (``predict``, a ``Prediction``), follows a growing one
  (``follow``, a ``Follower``) and infers its pile's material (``infer``, an ``Inference``);
* ``infer``: the posterior of the pile's material (``PosteriorModel``, read from a posterior
  file by ``load_posterior``; the predictive check's piles as ``PileSimulation`` says);
* ``report``: what ``Prediction`` and ``Inference`` share, and the interval's one name;
* ``follower``: the live forecast's loop, its own stop conditions (a signal, ``until``,
  ``# avalanche``), data one way: file -> line reader -> catalogue reader -> forecast;
* ``alarm``: the live forecast's alarm, the run's score, the picture drawn aside;
* ``catalogue``: a measured catalogue read (CSV, columns, bytes) with its measurement, and
  put at its tilt reached; ``files``: the model and posterior files read;
* ``common``: the defaults, the probability's text, JSON values, the provenance.

The commands (``sliders.runs.forecast``) parse, call this layer and print;
``sliders.forecast`` is its front door (``load()``).  Importing this package imports none of
its modules: ``python -m sliders.forecast predict --help`` reads ``common``'s defaults only.
"""
