"""The forecasting commands, ``python -m sliders.forecast`` (``cli``: the parser and ``main``).

Each parses, calls the forecasting layer (``sliders.forecasting``) and prints:

* ``cli``: the parser, the error boundary, the subcommands run by name;
* ``predict``: forecast a measured catalogue with a model file (``follow``: with ``--follow``);
* ``infer``: the posterior of the pile's material (``CHECK_SIMULATION``: the check's piles);
* ``evaluate``: fit, test and score every forecaster, publish the table, metrics, model, figures
  (``scoring``: the scores and tables; ``dev``: the serial development data);
* ``train``: run a prior ensemble and fit a model file;
* ``catalogue``: a simulated row written as a catalogue, the prior files' rows read;
* ``refusal``: the one line and the exit status of a refused input.
"""
