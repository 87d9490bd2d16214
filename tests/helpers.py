"""Plain helpers the test modules share (fixtures are in conftest.py).

Importing this module has no side effect: it installs no signal handler and
starts nothing; the clean-up at exit of the commands a test starts is
registered when the first one starts (``_Run``).
"""

from __future__ import annotations

import atexit
import ctypes
import ctypes.util
import math
import os
import queue
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import sliders
from sliders import keyed_random
from sliders.engine.contract import EVENT_FIELDS
from sliders.io import h5tools
from sliders.io.catalogue import EVENT_COLUMNS, Catalogue, CatalogueSet
from sliders.parts import loading


# ---------------------------------------------------------------------------
# commands run as processes (ensemble, prior, study, merge, ...)
# ---------------------------------------------------------------------------
# The tests pick the backend explicitly (no skipping).  "fortran" is the
# production kernel; the lead makes sure it is built in the final set-up.
BACKEND = "fortran"  # the production kernel (numpy works too, about 50x slower here)
MPIRUN = shutil.which("mpirun") or shutil.which("mpiexec")
PY = sys.executable
TIMEOUT = 180  # seconds for any single run; nothing should get close
# A tiny, fast scene: N = 10, the paper's parameters otherwise.
SCENE_OPTS = ["--n-sliders", "10", "--seed", "7"]
R = 10
# per-row values that depend on the run (the checksums cover the wall time)
RESULTS_IGNORED = {"wall_time", "row_crc32"}
# differ per run (the attributes' checksum covers the creation date)
ATTRS_IGNORED = {"created", "attrs_crc32", "date_created", "date_modified", "history"}

# tests/hooks/sitecustomize.py: the test hooks (SLIDERS_ENSEMBLE_TEST_DELAY, ..._TEST_FAIL,
# ..._STOP_AFTER), installed in every rank of a command started with this environment
HOOKS = Path(__file__).parent / "hooks"


def _env(**extra):
    env = dict(os.environ)
    env.pop("SLIDERS_ENSEMBLE_STOP_AFTER", None)
    env.pop("SLIDERS_ENSEMBLE_TEST_DELAY", None)
    env.pop("SLIDERS_ENSEMBLE_TEST_FAIL", None)
    env["PYTHONUNBUFFERED"] = "1"
    env["PYTHONPATH"] = os.pathsep.join([str(HOOKS)] + [p for p in [env.get("PYTHONPATH")] if p])
    env.update({k: str(v) for k, v in extra.items()})
    return env


def command(args, n=None, module="sliders.ensemble"):
    """The command line of ``python -m module``: plain python (n None) or mpirun -n n."""
    base = [PY, "-m", module]
    if n is not None:
        assert MPIRUN, "mpirun not found (install Debian mpich: scripts/setup.sh)"
        base = [MPIRUN, "-n", str(n)] + base
    return base + [str(a) for a in args]


def _children(pid: int) -> list[int]:
    out = []
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                stat = (p / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(p.name))
    return out


def kill_tree(pid: int) -> None:
    """SIGKILL a process started here and all its descendants (mpirun puts its proxy
    and the ranks in process groups of their own, so killpg is not enough)."""
    todo, seen = [pid], []
    while todo:
        p = todo.pop()
        seen.append(p)
        todo += _children(p)
    for p in seen:
        try:
            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass


_LIVE: "set[int]" = set()  # process trees started here and maybe still running


def _kill_live() -> None:
    """The runs live in sessions of their own (so that a kill reaches the whole tree):
    a Ctrl-C or SIGTERM of the test run must take them down with it."""
    for pid in sorted(_LIVE):
        kill_tree(pid)
    _LIVE.clear()


def _track(pid: int) -> None:
    """Remember a started process tree, and kill the ones still running at exit
    (registered with the first; nothing is registered at import)."""
    if not getattr(_track, "registered", False):
        atexit.register(_kill_live)
        _track.registered = True
    _LIVE.add(pid)


class _Run:
    """A started run whose stderr is read by a thread (so that waits can time out)."""

    def __init__(self, args, n, env, module="sliders.ensemble"):
        self.cmd = command(args, n, module)
        self.proc = subprocess.Popen(self.cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=env or _env(), start_new_session=True)
        _track(self.proc.pid)
        self.lines: "queue.Queue[str | None]" = queue.Queue()
        self.err: list[str] = []
        self.out: list[str] = []
        threading.Thread(target=self._pump, args=(self.proc.stderr, self.lines), daemon=True).start()
        threading.Thread(target=self._drain, args=(self.proc.stdout, self.out), daemon=True).start()

    @staticmethod
    def _pump(stream, q):
        for line in stream:
            q.put(line)
        q.put(None)

    @staticmethod
    def _drain(stream, sink):
        for line in stream:
            sink.append(line)

    def wait_for(self, predicate, timeout=TIMEOUT) -> None:
        """Collect stderr lines until predicate(lines) holds; fail (and kill) otherwise."""
        deadline = time.monotonic() + timeout
        while not predicate(self.err):
            try:
                line = self.lines.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                self.kill()
                pytest.fail(f"timed out waiting on {self.cmd}:\n{''.join(self.err)}")
            if line is None:
                pytest.fail(f"run ended early: {self.cmd}:\n{''.join(self.err)}")
            self.err.append(line)

    def finish(self, timeout=TIMEOUT) -> subprocess.CompletedProcess:
        try:
            self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            pytest.fail(f"run did not finish within {timeout} s (hang?): {self.cmd}\n"
                        f"{''.join(self.err)}")
        except KeyboardInterrupt:
            self.kill()
            raise
        _LIVE.discard(self.proc.pid)
        while True:
            try:
                line = self.lines.get(timeout=10)
            except queue.Empty:  # a stray descendant still holds the pipe
                break
            if line is None:
                break
            self.err.append(line)
        return subprocess.CompletedProcess(self.cmd, self.proc.returncode, "".join(self.out),
                                           "".join(self.err))

    def kill(self) -> None:
        kill_tree(self.proc.pid)
        _LIVE.discard(self.proc.pid)


def run(args, n=None, env=None, timeout=TIMEOUT, module="sliders.ensemble"):
    """Run to completion (or kill the whole process tree after ``timeout``)."""
    return _Run(args, n, env, module).finish(timeout)


def ensemble_args(out, r=R, backend=BACKEND, extra=()):
    return SCENE_OPTS + ["--realisations", r, "--out", out, "--backend", backend,
                         "--progress-interval", "0", *extra]


def rank_pids(mpirun_pid: int) -> list[int]:
    """PIDs of the rank processes below an mpirun (children of its hydra proxy), in rank order."""
    ranks = []
    for proxy in _children(mpirun_pid):
        for pid in _children(proxy):
            try:
                env = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
            except OSError:
                continue
            rank = next((int(e.split(b"=", 1)[1]) for e in env if e.startswith(b"PMI_RANK=")), None)
            if rank is not None:
                ranks.append((rank, pid))
    return [pid for _, pid in sorted(ranks)]


def progress_lines(k):
    return lambda lines: sum("ETA" in ln for ln in lines) >= k


def read_all(path):
    """{dataset path: array} and root attributes of a file."""
    import h5py

    data = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: data.__setitem__(n, o[()]) if isinstance(o, h5py.Dataset) else None)
        attrs = {k: h5tools.plain_value(v) for k, v in f.attrs.items()}
    return data, attrs


def assert_same_file(a, b, rows=None):
    """Same datasets (bitwise, wall times aside) and attributes (creation date aside).

    ``rows``: compare only these realisation rows of /realisations (default all).
    """
    da, aa = read_all(a)
    db, ab = read_all(b)
    assert sorted(da) == sorted(db)
    for k in da:
        if k.rsplit("/", 1)[-1] in RESULTS_IGNORED:
            continue
        x, y = da[k], db[k]
        if rows is not None and k.startswith("realisations/"):
            x, y = x[rows], y[rows]
        assert x.dtype == y.dtype, k
        assert x.shape == y.shape, k
        assert x.tobytes() == y.tobytes(), f"{k} differs between {a} and {b}"
    assert {k: v for k, v in aa.items() if k not in ATTRS_IGNORED} == \
        {k: v for k, v in ab.items() if k not in ATTRS_IGNORED}


def one_error_line(res):
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode != 0, res.stderr
    assert "Traceback" not in res.stderr, res.stderr
    assert len(lines) == 1, f"expected one line, got:\n{res.stderr}"
    assert lines[0].startswith("error: "), lines[0]
    return lines[0]


# ---------------------------------------------------------------------------
# the two backends compared (tests/test_backends.py)
# ---------------------------------------------------------------------------
ALPHA_TOL = 1e-9
DISPLACEMENT_TOL = 1e-7
ENERGY_TOL = 1e-9  # relative to max(1, |work of gravity|) of the event (see assert_same_run)


def assert_same_run(f: sliders.Result, n: sliders.Result) -> None:
    """The Fortran result f reproduces the NumPy result n, event by event."""
    assert (f.status, f.message) == (n.status, n.message)
    assert f.n_events == n.n_events
    for field in EVENT_FIELDS:
        assert f.events[field].dtype == n.events[field].dtype, field
    np.testing.assert_allclose(f.alpha, n.alpha, rtol=0, atol=ALPHA_TOL)
    np.testing.assert_array_equal(f.n_moved, n.n_moved)
    np.testing.assert_array_equal(f.events["n_stops"], n.events["n_stops"])
    # a crossing within rounding of a step boundary may add one (tiny) step
    np.testing.assert_allclose(f.n_steps, n.n_steps, rtol=0, atol=1)
    np.testing.assert_allclose(f.duration, n.duration, rtol=0, atol=f.scene.dt)
    # the unfinished last event (avalanche, cap): reported by both; a long
    # avalanche event amplifies last-bit differences, so only roughly equal
    assert f.final_event.keys() == n.final_event.keys()
    for key, value in f.final_event.items():
        np.testing.assert_allclose(value, n.final_event[key], rtol=0.05, err_msg=key)
    drift = np.zeros(f.n_events)
    if f.scene.record != "summary":
        np.testing.assert_array_equal(np.diff(f.displacement.ptr), f.n_moved)
        dense = np.abs(f.displacement.dense() - n.displacement.dense())
        assert dense.max(initial=0.0) <= DISPLACEMENT_TOL
        drift = dense.max(axis=1, initial=0.0)
    # energies: 1e-9 relative to the event's scale, plus what the (allowed)
    # displacement drift of the event implies: work = sin(alpha) sum du, the
    # elastic change ~ sum T du with tensions T of a few units, the path
    scale = np.maximum(1.0, np.abs(n.events["work_gravity"]))
    allowed = ENERGY_TOL * scale + 10.0 * n.n_moved * drift
    for field in ("work_gravity", "elastic_change", "dissipation"):
        err = np.abs(f.events[field] - n.events[field])
        assert np.all(err <= allowed), (field, (err / allowed).max())
    for which in ("initial", "final"):
        a, b = getattr(f, which), getattr(n, which)
        np.testing.assert_array_equal(a.n_stops, b.n_stops)
        # the draws agree to the last bit or two (NumPy's log/cos vs glibc's)
        np.testing.assert_allclose(a.mu_s, b.mu_s, rtol=1e-15, atol=0)
        np.testing.assert_allclose(a.displacement, b.displacement, rtol=0, atol=DISPLACEMENT_TOL)
        assert a.drive == pytest.approx(b.drive, abs=ALPHA_TOL)
    assert f.relaxation == n.relaxation
    if n.status == "avalanche":
        assert f.alpha_c == pytest.approx(n.alpha_c, abs=ALPHA_TOL)
    else:
        assert math.isnan(f.alpha_c) and math.isnan(n.alpha_c)


def assert_bit_for_bit(f: sliders.Result, n: sliders.Result) -> None:
    """Same events and states to the last bit (energies: other sums, 1e-12)."""
    assert (f.status, f.n_events) == (n.status, n.n_events)
    assert f.alpha_c == n.alpha_c or (math.isnan(f.alpha_c) and math.isnan(n.alpha_c))
    for field in ("drive", "n_moved", "n_stops", "n_steps", "slider_steps", "duration"):
        np.testing.assert_array_equal(f.events[field], n.events[field], err_msg=field)
    np.testing.assert_array_equal(f.displacement.ptr, n.displacement.ptr)
    np.testing.assert_array_equal(f.displacement.index, n.displacement.index)
    np.testing.assert_array_equal(f.displacement.value, n.displacement.value)
    for which in ("initial", "final"):
        a, b = getattr(f, which), getattr(n, which)
        np.testing.assert_array_equal(a.displacement, b.displacement)
        np.testing.assert_array_equal(a.mu_s, b.mu_s)
        np.testing.assert_array_equal(a.n_stops, b.n_stops)
    for field in ("work_gravity", "elastic_change", "dissipation"):
        np.testing.assert_allclose(f.events[field], n.events[field], rtol=1e-12, atol=1e-13)


def libm_reference(monkeypatch):
    """The reference with glibc's transcendentals (those the kernel calls).

    NumPy's own SIMD arcsin/arctan/hypot/log differ from glibc's in the last
    bit now and then (and Python's math.hypot is not glibc's either); with
    glibc's everywhere, the reference and the kernel do the same operations.
    """
    libm_path = ctypes.util.find_library("m")
    if libm_path is None:  # pragma: no cover - every Linux has it
        pytest.skip("no C math library found")
    libm = ctypes.CDLL(libm_path)
    funcs = {}
    for name, nargs in (("asin", 1), ("atan", 1), ("hypot", 2), ("log", 1), ("cos", 1)):
        f = getattr(libm, name)
        f.restype = ctypes.c_double
        f.argtypes = [ctypes.c_double] * nargs
        ufunc = np.frompyfunc(f, nargs, 1)
        funcs[name] = lambda *a, u=ufunc: np.asarray(u(*a), dtype=np.float64)

    for name in ("asin", "atan", "hypot"):
        monkeypatch.setitem(loading.TRANSCENDENTALS, name, funcs[name])
    for name in ("log", "cos"):
        monkeypatch.setitem(keyed_random.TRANSCENDENTALS, name, funcs[name])


# ---------------------------------------------------------------------------
# catalogues and forecasts
# ---------------------------------------------------------------------------
#: a catalogue of three events, as a file holds it
SMALL_CATALOGUE = "# three events\nangle [deg],size\n1.21,1\n2.03,1\n2.87,3\n"


def rate_law_catalogue(alpha_c, rate_a, tilt, displacement=0.01):
    """Events whose count grows as A log(alpha_c / (alpha_c - alpha)): rate A / (alpha_c - alpha)."""
    i = np.arange(1, 100000)
    alpha = alpha_c * (1.0 - np.exp(-i / rate_a))
    alpha = alpha[alpha <= tilt]
    n = alpha.size
    return Catalogue(alpha, np.ones(n), np.full(n, displacement), -np.ones(n), -np.ones(n),
                     tilt_now=tilt)


def synthetic_set(n_rows, seed=0):
    """Rows with rate-law catalogues (random alpha_c, rate and noise): fast training data."""
    rng = np.random.default_rng(seed)
    cats, ac = [], []
    for _ in range(n_rows):
        a_c = rng.uniform(0.3, 0.6)
        i = np.arange(1, 3000)
        alpha = a_c * (1.0 - np.exp(-(i + rng.uniform(0, 1, i.size)) / rng.uniform(30, 80)))
        alpha = np.sort(alpha[alpha < a_c])
        n = alpha.size
        cats.append(Catalogue(alpha, rng.integers(1, 5, n), rng.exponential(0.01, n),
                              -np.ones(n), -np.ones(n)))
        ac.append(a_c)
    return CatalogueSet.from_catalogues(cats, {"mu_d": np.tan(np.array(ac)) - 0.003}, ac,
                                        ["avalanche"] * n_rows)


def domain_check_of_piles_50_to_800():
    """``(check, train, cuts, catalogue)``: a domain check fitted on degraded cuts of
    ``synthetic_set(60, seed=1)`` whose rows hold 50 and 800 sliders in turn, and a catalogue
    like theirs cut at 0.25 rad."""
    from sliders.analysis.forecast import training_cuts
    from sliders.analysis.forecast.domain import DomainCheck
    from sliders.analysis.forecast.measurement import degrade_cuts

    train = synthetic_set(60, seed=1)
    rng = np.random.default_rng(0)
    cuts = degrade_cuts(training_cuts(train, 20, rng), rng)
    n = np.where(np.arange(len(train)) % 2, 50, 800)
    check = DomainCheck().fit(cuts, train.alpha_c, n_sliders=n)
    return check, train, cuts, synthetic_set(3, seed=9).catalogue(0).cut(0.25)


def accelerating(n: int = 150, seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """Angles (degrees) of ``n`` events accelerating towards 31° and their sizes."""
    rng = np.random.default_rng(seed)
    alpha = 31.0 - 31.0 * np.exp(-3.0 * np.sort(rng.random(n)))
    return np.round(alpha, 4), np.maximum(1, np.round(rng.pareto(1.5, n) + 1)).astype(int)


# ---------------------------------------------------------------------------
# priors, studies and model files
# ---------------------------------------------------------------------------
#: a small prior (format with R and design)
SMALL_PRIOR = """
[prior]
realisations = {R}
design = "{design}"
seed = 3
[scene]
mode = "explore"
[parameters]
mu_d = {{ uniform = [0.3, 0.8] }}
mu_s_minus_mu_d = {{ loguniform = [0.02, 0.12] }}
sigma_mu = {{ uniform = [0.005, 0.03] }}
xi = {{ loguniform = [1e-4, 1e-2], zero = 0.5 }}
n_sliders = {{ choice = [20, 30, 40] }}
"""
#: a small study of two points
STUDY_TEXT = """
[study]
realisations = 2
[scene]
n_sliders = 10
mode = "explore"
seed = 5
mu_d = 0.5
[axes]
xi = [0.0, 0.001]
"""
#: iterations of each boosted regressor kept in the reduced copy of the shipped model
ITERATIONS = 3


def assert_same_sets(a: CatalogueSet, b: CatalogueSet) -> None:
    """Every event, parameter, alpha_c, status and ceiling value equal, bit for bit."""
    assert np.array_equal(a.offsets, b.offsets)
    for c in EVENT_COLUMNS:
        assert np.array_equal(a.columns[c], b.columns[c]), c
    assert sorted(a.parameters) == sorted(b.parameters)
    for k in a.parameters:
        assert np.array_equal(a.parameters[k], b.parameters[k]), k
    assert np.array_equal(a.alpha_c, b.alpha_c, equal_nan=True)
    assert np.array_equal(a.status, b.status)
    assert np.array_equal(a.ceiling_alpha, b.ceiling_alpha)
    assert np.array_equal(a.ceiling_distance, b.ceiling_distance, equal_nan=True)


def write_model(path, forecasters, provenance, references=None):
    """A model file of ``forecasters`` as an adversary writes it: no check.  ``references``:
    the reference forecasts it carries (default: those ``forecasters`` give, or none if they
    give none)."""
    from sliders.analysis.forecast import arrays
    from sliders.io.model_arrays import model_arrays_bytes

    content, parts = arrays.to_arrays(forecasters)
    cases = arrays.reference_catalogues()
    if references is None:
        try:
            references = arrays.reference_outputs(forecasters, arrays.reference_cuts(cases))
        except Exception:  # noqa: BLE001 (a broken model: it carries no reference forecasts)
            references = {}
    parts.update({f"reference.{k}": np.asarray(v) for k, v in
                  {**arrays.catalogue_arrays(cases), **references}.items()})
    Path(path).write_bytes(model_arrays_bytes({"content": content, "provenance": provenance},
                                              parts))
    return path


# -- the shipped model's forecasts before its conversion to arrays ----------------------
def forecasts_before_arrays() -> dict:
    """What the shipped forecaster and posterior gave when read as scikit-learn's and crepes's
    fitted objects (``tests/test_model_arrays.py``)."""
    with np.load(Path(__file__).parent / "data" / "forecasts_before_arrays.npz",
                 allow_pickle=False) as z:
        return dict(z)


def recorded_cases(ref):
    """The recorded catalogues with their measurements (``case.catalogue.*``, as
    ``arrays.catalogue_arrays`` writes them), and the same kept to angles and sizes."""
    from sliders.analysis.forecast.arrays import CATALOGUE_COLUMNS
    from sliders.analysis.forecast.measurement import Measurement
    from sliders.forecasting.catalogue import angles_and_sizes
    from sliders.io.catalogue import Catalogue

    a = {k[len("case.catalogue."):]: v for k, v in ref.items() if k.startswith("case.catalogue.")}
    cases = []
    for i, (lo, hi) in enumerate(zip(a["start"][:-1], a["start"][1:])):
        r, ms, mf, arbitrary, n = a["measurement"][i]  # recorded before a camera's columns
        m = Measurement(float(r), float(ms), float(mf), "arbitrary" if arbitrary else "sliders",
                        int(n) if n else None)
        cases.append((Catalogue(*(a[c][lo:hi] for c in CATALOGUE_COLUMNS),
                                tilt_now=float(a["tilt_now"][i])), m))
    return cases, [(angles_and_sizes(c)[0], m) for c, m in cases]


def cuts_of_cases(cases):
    """The ``Cuts`` of ``[(Catalogue, Measurement)]``, each measured as it was."""
    from sliders.analysis.forecast.features import Cuts

    return Cuts([c for c, _ in cases], np.full(len(cases), -1, dtype=np.int64),
                measurement=[m for _, m in cases])


def model_outputs(forecasters, posterior, cases, blind) -> dict:
    """What ``forecasts_before_arrays`` records, computed again."""
    out = {}
    for kind, cs in (("full", cases), ("blind", blind)):
        cuts = cuts_of_cases(cs)
        for name, f in forecasters.items():
            q, fb, lv = f.quantiles(cuts, levels=True)
            out |= {f"{kind}.{name}.quantiles": q, f"{kind}.{name}.fallback": fb,
                    f"{kind}.{name}.levels": lv}
            if hasattr(f, "_raw_log_remaining"):
                out[f"{kind}.{name}.raw"] = f._raw_log_remaining(cuts)
                out[f"{kind}.{name}.inside"] = f.domain(cuts)[0]
        out[f"{kind}.posterior.quantiles"] = posterior.quantiles(cuts)
        out[f"{kind}.posterior.inside"] = posterior.domain(cuts)[0]
    return out


# -- the code that reads and checks a model file ---------------------------------------
_F = "sliders.analysis.forecast."
#: the source that reads a model file and checks it (its form, the header's schema, every
#: fitted part, the expected-accuracy tables, the reference forecasts): "module" for all of a
#: module, "module:Qualified.name" for a function, a class or an assignment (a class's FIELDS)
MODEL_FILE_READING = (
    *(f"sliders.io.model_arrays:{n}" for n in ("read_model_arrays", "ModelArchive", "_member")),
    *(f"sliders.io.forecast_model:{n}" for n in (
        "read_model_bytes", "check_digest", "printable_tree")),
    _F + "model_file:load_forecasters", _F + "model_file:ModelForecasters", _F + "integrity",
    *(f"{_F}arrays:{n}" for n in ("_decode", "check_references",
                                  "estimator_of", "references_of")),
    *(f"{_F}evaluators:{n}" for n in (
        "Arrays", "_nodes", "QuantileTrees.FIELDS", "QuantileTrees.FILE_NAMES",
        "QuantileTrees.check_consistent", "ResidualTable.FIELDS", "ResidualTable.check_consistent",
        "NoveltyDetector.FIELDS", "NoveltyDetector.check_consistent")),
    *(f"{_F}learned:{n}" for n in ("Learned.FIELDS", "Learned.check_consistent", "ALARM_SKILL")),
    *(f"{_F}posterior:{n}" for n in (
        "_n_p", "ParameterPosterior._check_range", "ParameterPosterior.FIELDS",
        "ParameterPosterior.check_fitted", "ParameterPosterior.check_consistent")),
    _F + "domain:DomainCheck.FIELDS", _F + "domain:DomainCheck.check_consistent",
    _F + "baselines:Climatology.FIELDS", _F + "physics:ModelBased.FIELDS",
    _F + "inverse_rate:_InverseRate.FIELDS", _F + "base:Forecaster.check_fitted",
    _F + "evaluation:_leads", _F + "evaluation:ACCURACY_RANGES", _F + "evaluation:ACCURACY_FIELDS")
