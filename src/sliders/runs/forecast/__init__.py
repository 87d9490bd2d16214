"""The forecasting commands, ``python -m sliders.forecast`` (``cli``: the parser and ``main``).

* ``cli``: the parser, the error boundary, the subcommands run by name;
* ``evaluate``: fit, test and score every forecaster, publish the table, metrics, model, figures
  (``scoring``: the scores and tables; ``dev``: the serial development data);
* ``predict``: forecast a measured catalogue with a model file;
* ``train``: run a prior ensemble and fit a model file;
* ``catalogue``: a measured catalogue and its measurement read, a simulated row written as one;
* ``common``: the defaults, a prior file read, the provenance of what the commands write.
"""
