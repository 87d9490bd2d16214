"""The live forecast's alarm, the run scored at its end, and the live picture drawn aside.

Three pieces of ``predict --follow`` (``follower.py``), each usable alone:

``Alarm``
    P(avalanche within the horizon) of each update's first method against a
    threshold, with hysteresis: the alarm rises when P reaches ``threshold``
    and stays raised until P falls below the release level, ``release``
    (default ``default_release(threshold)``: ``threshold - 0.1``, or half the
    threshold below 0.2).  A forecast's P moves from row to row by a few
    hundredths as events arrive; without the gap an alarm whose P hovers at
    the threshold sounds and stops at every row.  One ``ALARM`` line per alarm
    raised and one ``alarm off`` line per release; with ``hook`` (the text of
    ``--on-alarm 'CMD ARGS'``, split as a shell splits words and run without a
    shell) the command runs once per alarm raised, not waited on, the forecast
    in its environment (``HOOK_ENVIRONMENT``); a hook that fails is reported in
    one line, and the follow goes on.
``RunScore``
    The updates of a follow, scored at the avalanche: when the alarm first
    rose and how far before, the last forecast and its error, the share of the
    intervals that held the avalanche.
``LatestPicture``
    ``--plot``'s PNG drawn aside (a thread that forks a process at a lower
    priority for each picture; Matplotlib's Agg canvas on ``Figure`` objects,
    no pyplot state), so that the picture does not hold up the next forecast:
    a newer prediction replaces one still waiting to be drawn, so the picture
    is never more than one update behind.
"""

from __future__ import annotations

import gc
import math
import os
import shlex
import shutil
import signal
import subprocess
import threading

from ..analysis.forecast.base import LEVELS
from ..io.forecast_files import ForecastInputError
from ..io.safeio import publish_bytes
from .common import probability_text
from .report import interval_name

#: the release level's gap below the threshold (``default_release``)
RELEASE_GAP = 0.1
#: the priority the picture is drawn at, below the forecast's (``os.nice``'s increment)
PICTURE_NICENESS = 10

#: what a hook finds in its environment (besides the follower's own), values as text
HOOK_ENVIRONMENT = {
    "SLIDERS_ALARM_P": "P(avalanche within the horizon) of the first method, a number",
    "SLIDERS_ALARM_P_TEXT": "the same as the ALARM line prints it ('= 0.62', '> 0.95')",
    "SLIDERS_ALARM_THRESHOLD": "the alarm's threshold",
    "SLIDERS_ALARM_WITHIN_DEG": "the alarm's horizon, degrees",
    "SLIDERS_ALARM_ANGLE_DEG": "the forecast avalanche angle (the median), degrees",
    "SLIDERS_ALARM_LOW_DEG": "the low end of the forecast interval, degrees",
    "SLIDERS_ALARM_HIGH_DEG": "the high end of the forecast interval, degrees",
    "SLIDERS_ALARM_CALIBRATED": "1 if the interval is calibrated (80 %), else 0",
    "SLIDERS_TILT_DEG": "the tilt reached, degrees",
    "SLIDERS_ROWS": "the complete rows read",
    "SLIDERS_CATALOGUE": "the catalogue followed (empty if unknown)",
}


def resolved_probabilities() -> tuple[float, float]:
    """The least and the greatest P(within) a forecast resolves (its quantile levels' ends):
    beyond them the text gives a bound and JSON the bound's value."""
    return float(LEVELS[0]), float(LEVELS[-1])


def threshold_option(value, option: str = "--alarm-threshold") -> float:
    """A threshold of ``option`` that P(within) can reach and fall below: above the least
    probability a forecast resolves, at most the greatest; or one line naming it."""
    try:
        p = float(value)
    except (TypeError, ValueError):
        raise ForecastInputError(f"{option} {value}: a probability, e.g. 0.5") from None
    lo, hi = resolved_probabilities()
    if not 0.0 < p < 1.0:
        raise ForecastInputError(f"{option} {value}: a probability strictly between 0 and 1")
    if not lo < p <= hi:
        raise ForecastInputError(f"{option} {value}: the forecasts resolve P(within) from {lo:g} "
                                 f"to {hi:g} (beyond, '< {lo:g}' and '> {hi:g}'), so the alarm "
                                 f"would {'always' if p <= lo else 'never'} sound; give a "
                                 f"threshold above {lo:g} and at most {hi:g}")
    return p


def single_alarm(report: dict, threshold) -> tuple[dict, str]:
    """A single forecast's alarm at ``threshold`` (no hysteresis): ``report`` (its JSON object)
    with ``alarm_threshold`` and ``alarm``, and the line that says it."""
    t = threshold_option(threshold)
    on = probability_within(report) >= t
    m = _first_method(report)
    text = probability_text(float(report["probability_within"]),
                            m.get("probability_bounds", (0.0, 1.0)))
    line = (f"alarm: P(avalanche within the next {math.degrees(report['within']):g}°) {text}, "
            + (f"at or above the threshold {t:g}: ALARM" if on else
               f"below the threshold {t:g}: no alarm"))
    return report | {"alarm_threshold": t, "alarm": on}, line


def alarm_skill_line(forecaster, default: float, used: float | None = None) -> str:
    """What ``forecaster``'s alarm did on held-out piles followed to their avalanche
    (``alarm_skill_``, measured at its ``default`` threshold by benchmarks/alarm_skill.py), and
    the threshold in use (``used``; None: the default), in one line."""
    used = default if used is None else threshold_option(used)
    skill = getattr(forecaster, "alarm_skill_", None)
    head = f"alarm: at P(avalanche within the next degree) ≥ {used:g} ({forecaster.label})"
    if not skill:
        return head + "; the model file holds no measure of this alarm on held-out piles"
    return (f"{head}; at its default {default:g}, on {skill['piles']} held-out piles followed "
            f"to their avalanche, it rose before the avalanche for {skill['hit_share']:.0%} of "
            f"them, a median {skill['warning_median_deg']:.2f}° before (10th percentile "
            f"{skill['warning_p10_deg']:.2f}°), and more than 3° early for "
            f"{skill['false_alarm_share']:.0%}")


def default_release(threshold: float) -> float:
    """The level below which a raised alarm is released: ``RELEASE_GAP`` below the threshold,
    or half the threshold if that is smaller (a low threshold keeps a level to fall below)."""
    return threshold - min(RELEASE_GAP, threshold / 2.0)


def check_release(release, threshold: float, option: str = "--alarm-release") -> float:
    """A release level in [0, ``threshold``), or one line naming ``option``."""
    try:
        r = float(release)
    except (TypeError, ValueError):
        raise ForecastInputError(f"{option} {release}: a probability, e.g. 0.4") from None
    if not 0.0 <= r < threshold:
        raise ForecastInputError(f"{option} {release}: the release level must lie in [0, the "
                                 f"alarm threshold {threshold:g})")
    return r


def check_hook(text) -> list[str]:
    """The words of ``--on-alarm 'CMD ARGS'`` (split as a shell splits them), its program
    found; else one line naming the option (called before the follow starts)."""
    try:
        words = shlex.split(str(text))
    except ValueError as exc:
        raise ForecastInputError(f"--on-alarm {text}: {exc} (give the command as one "
                                 "argument, quoted as for a shell)") from None
    if not words:
        raise ForecastInputError("--on-alarm: give the command to run, e.g. "
                                 "--on-alarm 'notify-send ALARM'")
    if shutil.which(words[0]) is None:
        where = "no such file, or not executable" if os.sep in words[0] else \
            "no such program on the PATH"
        raise ForecastInputError(f"--on-alarm {text}: {words[0]}: {where}")
    return words


def _first_method(prediction) -> dict:
    """The first method's entry of ``prediction`` (a ``Prediction`` or its ``to_dict()``)."""
    methods = prediction["methods"]
    return methods[next(iter(methods))]


def probability_within(prediction) -> float:
    """P(within) of the first method of ``prediction``, as its distribution gives it (JSON's
    ``probability_within`` is clipped to the probabilities the forecast resolves)."""
    m = _first_method(prediction)
    return float(m.get("probability_within_raw", prediction["probability_within"]))


class Alarm:
    """The alarm of a live forecast, with hysteresis (module docstring).

    Parameters
    ----------
    threshold : float or None
        P(avalanche within the horizon) at or above which the alarm rises, above the least
        probability a forecast resolves and at most the greatest (``threshold_option``);
        None: each prediction's own ``alarm_threshold`` (the forecaster's).
    release : float, optional
        P below which a raised alarm falls, in [0, threshold); default
        ``default_release(threshold)``.
    hook : str, optional
        ``--on-alarm``'s command text, run once per alarm raised (``check_hook`` refuses one
        that cannot start).
    say : callable
        ``say(line)`` prints one line (the ALARM and alarm-off lines, a hook's failure).
    catalogue : str, optional
        The catalogue followed, for the hook's ``SLIDERS_CATALOGUE``.
    """

    def __init__(self, threshold: float | None, release: float | None = None,
                 hook: str | None = None, say=print, catalogue: str | None = None):
        self.threshold = None if threshold is None else threshold_option(threshold)
        self._release = release
        if release is not None and self.threshold is not None:
            self._release = check_release(release, self.threshold)
        self.argv = None if hook is None else check_hook(hook)
        self.hook = hook
        self.say = say
        self.catalogue = catalogue
        self.on = False
        self.raised_count = 0
        self.hooks: list[subprocess.Popen] = []  # the hooks started and not seen to end
        self._waiters: list[threading.Thread] = []

    def levels(self, prediction) -> tuple[float, float]:
        """``(threshold, release)`` for ``prediction``."""
        t = self.threshold if self.threshold is not None else float(prediction["alarm_threshold"])
        if self._release is None:
            return t, default_release(t)
        return t, check_release(self._release, t)

    def update(self, prediction, rows: int) -> dict:
        """The alarm after ``prediction`` (a ``Prediction`` or its ``to_dict()``) of ``rows``
        complete rows: ``{"alarm", "raised", "released"}``; a line when it rises or falls, and
        the hook run when it rises."""
        t, r = self.levels(prediction)
        p = probability_within(prediction)
        raised = not self.on and p >= t
        released = self.on and p < r
        if raised:
            self.on = True
            self.raised_count += 1
            self.say(self.alarm_line(prediction, rows, t))
            if self.argv is not None:
                self._run_hook(prediction, rows, t)
        elif released:
            self.on = False
            self.say(self.off_line(prediction, rows, r))
        return {"alarm": self.on, "raised": raised, "released": released}

    @staticmethod
    def _p_text(prediction) -> str:
        m = _first_method(prediction)
        return probability_text(float(prediction["probability_within"]),
                                m.get("probability_bounds", (0.0, 1.0)))

    def alarm_line(self, prediction, rows: int, threshold: float) -> str:
        """The ALARM line: where, P as the update line prints it, the forecast."""
        deg = math.degrees
        method = next(iter(prediction["methods"]))
        m = prediction["methods"][method]
        lo, hi = prediction["interval"]
        return (f"ALARM at {deg(prediction['tilt_now']):.2f}° (rows {rows}): P(avalanche within "
                f"the next {deg(prediction['within']):g}°) {self._p_text(prediction)}, at or "
                f"above the threshold {threshold:g}; avalanche angle "
                f"{deg(prediction['alpha_c']):.2f}° ({interval_name(m, method)} {deg(lo):.2f}-"
                f"{deg(hi):.2f}°)")

    def off_line(self, prediction, rows: int, release: float) -> str:
        """The alarm-off line: where, P, the release level it fell below."""
        deg = math.degrees
        return (f"alarm off at {deg(prediction['tilt_now']):.2f}° (rows {rows}): P(avalanche "
                f"within the next {deg(prediction['within']):g}°) {self._p_text(prediction)}, "
                f"below the release level {release:g}")

    def environment(self, prediction, rows: int, threshold: float) -> dict:
        """The hook's variables (``HOOK_ENVIRONMENT``) for ``prediction``."""
        deg = math.degrees
        method = next(iter(prediction["methods"]))
        m = prediction["methods"][method]
        lo, hi = prediction["interval"]
        return {"SLIDERS_ALARM_P": f"{float(prediction['probability_within']):.6g}",
                "SLIDERS_ALARM_P_TEXT": self._p_text(prediction),
                "SLIDERS_ALARM_THRESHOLD": f"{threshold:g}",
                "SLIDERS_ALARM_WITHIN_DEG": f"{deg(prediction['within']):.6g}",
                "SLIDERS_ALARM_ANGLE_DEG": f"{deg(prediction['alpha_c']):.4f}",
                "SLIDERS_ALARM_LOW_DEG": f"{deg(lo):.4f}",
                "SLIDERS_ALARM_HIGH_DEG": f"{deg(hi):.4f}",
                "SLIDERS_ALARM_CALIBRATED": "1" if m.get("calibrated", False) else "0",
                "SLIDERS_TILT_DEG": f"{deg(prediction['tilt_now']):.4f}",
                "SLIDERS_ROWS": str(int(rows)),
                "SLIDERS_CATALOGUE": "" if self.catalogue is None else str(self.catalogue)}

    def _run_hook(self, prediction, rows: int, threshold: float) -> None:
        """Start the hook (its output on stderr, in a session of its own so that a Ctrl-C of
        the follow does not cut it short) and watch it from a thread."""
        env = os.environ | self.environment(prediction, rows, threshold)
        try:
            proc = subprocess.Popen(self.argv, env=env, stdin=subprocess.DEVNULL, stdout=2,
                                    start_new_session=True)
        except OSError as exc:
            self.say(f"--on-alarm {self.hook}: could not start: {exc.strerror or exc}; the "
                     "follow goes on")
            return
        self.hooks = [h for h in self.hooks if h.returncode is None] + [proc]
        waiter = threading.Thread(target=self._watch, args=(proc,), daemon=True,
                                  name="sliders-alarm-hook")
        waiter.start()
        self._waiters = [w for w in self._waiters if w.is_alive()] + [waiter]

    def _watch(self, proc: subprocess.Popen) -> None:
        code = proc.wait()
        if code != 0:
            how = (f"killed by signal {-code}" if code < 0 else f"exited with status {code}")
            self.say(f"--on-alarm {self.hook}: {how}; the follow goes on")

    def wait_hooks(self, timeout: float | None = None) -> bool:
        """Wait (at most ``timeout`` seconds) for the hooks started to end and be reported;
        True if none is left running."""
        for w in list(self._waiters):
            w.join(timeout)
        return not any(w.is_alive() for w in self._waiters)


class RunScore:
    """The updates of a follow, scored at the avalanche.

    ``add(update)`` takes each update as the follower prints it with ``--json``: the
    prediction's ``to_dict()`` with ``rows`` and ``alarm``; ``summary(avalanche_angle)`` scores
    them (JSON values, radians), ``lines(summary)`` says it in text.
    """

    def __init__(self):
        self.updates: list[dict] = []

    def add(self, update: dict) -> None:
        """Keep what the score reads of one update."""
        self.updates.append({"tilt_now": float(update["tilt_now"]),
                             "alpha_c": float(update["alpha_c"]),
                             "interval": [float(x) for x in update["interval"]],
                             "rows": int(update["rows"]), "alarm": bool(update["alarm"]),
                             "calibrated": bool(_first_method(update).get("calibrated", True))
                             if "methods" in update else None})

    def summary(self, avalanche_angle: float | None = None) -> dict:
        """The score (radians): ``avalanche_angle`` as given (the ``# avalanche ANGLE`` line)
        or else the last tilt reached (``avalanche_angle_source`` says which), the first alarm
        (tilt, rows, how far before), the last forecast and its error, the share of the
        updates' intervals that held the avalanche."""
        u = self.updates
        if avalanche_angle is not None:
            a, source = float(avalanche_angle), "given"
        elif u:
            a, source = u[-1]["tilt_now"], "last tilt reached"
        else:
            a, source = None, None
        out = {"avalanche_angle": a, "avalanche_angle_source": source,
               "updates": len(u), "alarms_raised": 0, "first_alarm": None,
               "last_forecast": None, "interval_held": None, "interval_held_share": None}
        if not u:
            return out
        prev = False
        for x in u:
            if x["alarm"] and not prev:
                out["alarms_raised"] += 1
                if out["first_alarm"] is None:
                    out["first_alarm"] = {"tilt_now": x["tilt_now"], "rows": x["rows"],
                                          "before": a - x["tilt_now"]}
            prev = x["alarm"]
        last = u[-1]
        held = sum(1 for x in u if x["interval"][0] <= a <= x["interval"][1])
        out["last_forecast"] = {"tilt_now": last["tilt_now"], "rows": last["rows"],
                                "alpha_c": last["alpha_c"], "interval": last["interval"],
                                "calibrated": last["calibrated"], "error": last["alpha_c"] - a,
                                "held": bool(last["interval"][0] <= a <= last["interval"][1])}
        out["interval_held"] = held
        out["interval_held_share"] = held / len(u)
        return out

    @staticmethod
    def lines(summary: dict) -> list[str]:
        """The summary as text (degrees)."""
        a = summary["avalanche_angle"]
        if summary["updates"] == 0 or a is None:
            return ["run: no forecast was made"]
        deg = math.degrees
        where = ("given on the '# avalanche' line" if summary["avalanche_angle_source"] == "given"
                 else "the last tilt reached; write it as '# avalanche 28.85deg' to score against "
                      "the angle measured")
        out = [f"run scored at the avalanche angle {deg(a):.2f}° ({where}): "
               f"{summary['updates']} update{'s' if summary['updates'] != 1 else ''}"]
        first = summary["first_alarm"]
        if first is None:
            out.append("alarm: never raised")
        else:
            out.append(f"alarm: first raised at {deg(first['tilt_now']):.2f}° (rows "
                       f"{first['rows']}), {deg(first['before']):.2f}° before the avalanche; "
                       f"raised {summary['alarms_raised']} time"
                       f"{'s' if summary['alarms_raised'] != 1 else ''}")
        last = summary["last_forecast"]
        lo, hi = last["interval"]
        name = "80 % interval" if last["calibrated"] in (True, None) else \
            "widened interval, uncalibrated"
        out.append(f"last forecast at {deg(last['tilt_now']):.2f}° (rows {last['rows']}): "
                   f"{deg(last['alpha_c']):.2f}° ({name} {deg(lo):.2f}-{deg(hi):.2f}°), error "
                   f"{deg(last['error']):+.2f}°, the avalanche "
                   f"{'inside' if last['held'] else 'outside'} its interval")
        out.append(f"intervals that held the avalanche: {summary['interval_held']} of "
                   f"{summary['updates']} ({summary['interval_held_share']:.2f})")
        return out


def png_bytes(prediction, status: dict | None = None) -> bytes:
    """The bench picture of ``prediction`` as PNG bytes, drawn as a Figure of its own (no
    pyplot, so safe in a thread: saving it as PNG draws it on an Agg canvas); ``status``
    (``"alarm"``, ``"alarm_threshold"``, ``"time"``, ``"rows"``, ``"file"``) the live picture's
    banner (``figures.bench.bench_figure``)."""
    return prediction.png(status=status)


class LatestPicture:
    """``--plot``'s picture, drawn and written aside from the forecast, the newest only.

    ``show(prediction, status)`` hands the newest prediction over and returns at once; if one
    is being drawn, the new one waits, replacing any that waited before it (never more than
    one update behind).  ``close()`` waits for the last picture.  A failure to write the file
    is raised (``ForecastInputError``, one line naming the path) from the next ``check``,
    ``show`` or ``close``, once; nothing is drawn after it.  A follow calls ``check`` at
    every poll, so that a failure is told even when no update follows it.

    A thread of this object takes each prediction; where the system forks (POSIX) it draws it
    in a child process forked for the picture, at a lower priority (``PICTURE_NICENESS``), and
    waits for it.  In a thread of the follower's own process the drawing (Python, most of
    it) would hold the interpreter's lock against the next forecast: measured here, a forecast
    of 0.06 s took 0.25 s while a picture was drawn beside it.  The forked child shares the
    prediction without copying it, and a core runs the next forecast first.

    Parameters
    ----------
    path : str or os.PathLike
        The PNG, replaced whole at each picture (``safeio.publish_bytes``).
    draw : callable
        ``draw(prediction, status) -> bytes``: the PNG (default ``png_bytes``).
    fork : bool, optional
        Draw in a forked child (default: where ``os.fork`` exists); False: in the thread.
    """

    def __init__(self, path, draw=png_bytes, fork: bool | None = None):
        self.path = os.fspath(path)
        self.draw = draw
        self.fork = hasattr(os, "fork") if fork is None else bool(fork)
        self.drawn = 0  # pictures written
        self.shown = 0  # predictions handed over
        self.child: int | None = None  # the process drawing a picture, while it does
        self._cond = threading.Condition()
        self._pending = None
        self._busy = False
        self._closed = False
        self._error: BaseException | None = None
        if self.fork and draw is png_bytes:
            from ..figures import bench  # noqa: F401 - imported once here, not in each child
        self._thread = threading.Thread(target=self._run, daemon=True, name="sliders-picture")
        self._thread.start()

    def show(self, prediction, status: dict | None = None) -> None:
        """Draw ``prediction`` next (replacing one that waits); ``status`` what the picture
        says beside the forecast."""
        with self._cond:
            self._raise_error()
            self._pending = (prediction, dict(status or {}))
            self.shown += 1
            self._cond.notify_all()

    def check(self) -> None:
        """Raise a failure to write the picture now, if one came (once)."""
        with self._cond:
            self._raise_error()

    def behind(self) -> int:
        """Updates handed over but not yet written: 0, 1 or 2 (one drawn, one waiting)."""
        with self._cond:
            return int(self._busy) + int(self._pending is not None)

    def _raise_error(self) -> None:
        if self._error is not None:
            exc, self._error = self._error, None
            self._closed = True
            raise exc

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait()
                if self._pending is None or self._error is not None:
                    return
                item, self._pending = self._pending, None
                self._busy = True
            try:
                error = self._draw_in_child(item) if self.fork else self._draw_here(item)
            except BaseException as exc:  # noqa: BLE001 - a fault, raised in the caller's thread
                error = exc
            with self._cond:
                self._busy = False
                if error is None:
                    self.drawn += 1
                else:
                    self._error, self._pending = error, None
                self._cond.notify_all()
                if error is not None:
                    return

    def _write_error(self, exc: BaseException) -> ForecastInputError:
        return ForecastInputError(f"{self.path}: the picture could not be written: "
                                  f"{getattr(exc, 'strerror', None) or exc}")

    def _draw_here(self, item) -> BaseException | None:
        """Draw and write ``item`` in this thread; the write's failure returned."""
        data = self.draw(*item)
        try:
            publish_bytes(self.path, data, overwrite=True)
        except (OSError, ValueError) as exc:
            return self._write_error(exc)
        return None

    def _draw_in_child(self, item) -> BaseException | None:
        """Draw and write ``item`` in a forked child; its failure returned (a write's as
        ``ForecastInputError``, a fault as ``RuntimeError``), in one line."""
        read_end, write_end = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: draw, write, and leave without the parent's exit handlers
            code, message = 0, ""
            try:
                # a Ctrl-C or SIGTERM of the follow reaches this child too: the picture is
                # finished (a second or two), never left half-written beside the PNG
                for signum in (signal.SIGINT, signal.SIGTERM):
                    signal.signal(signum, signal.SIG_IGN)
                gc.disable()  # a collection would touch (and copy) the whole shared heap
                os.close(read_end)
                try:
                    os.nice(PICTURE_NICENESS)
                except OSError:
                    pass
                error = self._draw_here(item)
                if error is not None:
                    code, message = 2, str(error)
            except BaseException as exc:  # noqa: BLE001 - said to the parent, in one line
                code, message = 3, f"{type(exc).__name__}: {' '.join(str(exc).split())}"
            finally:
                if code:
                    os.write(write_end, message.encode("utf-8", "replace")[:4000])
                os._exit(code)
        self.child = pid
        os.close(write_end)
        with os.fdopen(read_end, "rb") as fh:
            message = fh.read().decode("utf-8", "replace")
        code = os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])
        self.child = None
        if code == 0:
            return None
        if code == 2:
            return ForecastInputError(message)
        if code < 0:
            return RuntimeError(f"the process drawing {self.path} was killed by signal "
                                f"{-code}")
        return RuntimeError(f"drawing {self.path}: {message or f'status {code}'}")

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until every prediction handed over is drawn (or failed); True if so."""
        with self._cond:
            return self._cond.wait_for(lambda: not self._busy and self._pending is None,
                                       timeout)

    def close(self) -> None:
        """Wait for the last picture; its failure (or an earlier one not yet raised) raised."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join()
        with self._cond:
            self._raise_error()
