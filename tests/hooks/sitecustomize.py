"""Test hooks for run commands started as subprocesses (``mpirun -n 2 python -m sliders.ensemble``).

The test helpers put this folder first on ``PYTHONPATH`` when they set one of
the variables below; Python imports ``sitecustomize`` at start-up in every
rank, and this module wraps the scheduler's functions (the production code
reads no such variable):

``SLIDERS_ENSEMBLE_TEST_DELAY=S``: every row starts with a sleep of S seconds
(then a progress callback), so that a test can signal or kill a run that is
still going;
``SLIDERS_ENSEMBLE_TEST_FAIL=r``: row r raises RuntimeError (an unexpected
failure on one rank mid-run);
``SLIDERS_ENSEMBLE_STOP_AFTER=K``: rank 0 behaves as if it received SIGTERM
once K rows have been completed in this run.
"""

import os
import signal
import time

_DELAY = os.environ.get("SLIDERS_ENSEMBLE_TEST_DELAY")
_FAIL = os.environ.get("SLIDERS_ENSEMBLE_TEST_FAIL")
_STOP_AFTER = os.environ.get("SLIDERS_ENSEMBLE_STOP_AFTER")

if _DELAY or _FAIL or _STOP_AFTER:
    from sliders.runs import scheduler

    _compute = scheduler.compute

    def compute(ctx, r, progress):
        if _DELAY:
            time.sleep(float(_DELAY))
            progress(None)
        if _FAIL is not None and str(r) == _FAIL:
            raise RuntimeError(f"test hook SLIDERS_ENSEMBLE_TEST_FAIL: row {r} fails")
        return _compute(ctx, r, progress)

    scheduler.compute = compute

    if _STOP_AFTER:
        _completed = scheduler.Root.completed

        def _completed_then_stop(self, code):
            _completed(self, code)
            if self.done_now >= int(_STOP_AFTER):
                self.stop(f"test hook SLIDERS_ENSEMBLE_STOP_AFTER={_STOP_AFTER}", signal.SIGTERM)

        scheduler.Root.completed = _completed_then_stop
