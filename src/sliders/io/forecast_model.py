"""The fitted forecasters' file: data, never code.

A model file is an archive of fitted objects (``io.model_archive``: a zip of one
JSON tree and a few packed NumPy arrays) of one dict::

    {"format": MODEL_FORMAT, "forecasters": {method: fitted forecaster},
     "provenance": {prior, rows, mode, versions, date, ...}}

Loading never runs code from the file: before anything is imported or built, every
class or function the tree names must be on ``ALLOWED_NAMES``, an explicit list of what
the package writes; anything else (a pickle, a tree naming another class or a
function) is refused in one line.

The file is read as data within bounds, before anything is built: a regular
file of at most ``MAX_MODEL_BYTES``, read once; a zip of at most ``MAX_MEMBERS``
members whose declared sizes (``zipfile`` inflates no more than a member
declares) are bounded, each and together (``MAX_MEMBER_BYTES``,
``MAX_INFLATED_BYTES``: no zip bomb), its JSON tree at most ``MAX_TREE_BYTES``; every NumPy member's header read first, its
array of a numeric dtype and exactly the size its member declares.  After the
objects are built and before any forecast, every forecaster checks every part a
forecast reads (``check_fitted``: the trees' child indices, features and
leaves, the calibration, the climatology, the domain check;
``analysis.forecast.integrity``).  A file that fails any step is refused in one
line naming it and what is wrong (``ModelFileError``).  The provenance comes
back with every string made printable (``safeio.printable``).

The default model ships inside the package (``sliders/data/``, found with
``importlib.resources``), never looked up in the current folder, and is checked by its
SHA-256 (``DEFAULT_MODEL_NAME + ".sha256"`` beside it), which stands for the archive's
member-by-member check (the suite runs that check on the shipped bytes); its forecasters are
checked as any file's.  So is the shipped posterior of ``infer``
(``DEFAULT_POSTERIOR_NAME``), a model file of one entry.
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import importlib.resources
import io
import os
import pathlib
import stat
import sys
import zipfile

import numpy as np

from . import model_archive
from .safeio import printable, publish_bytes


MODEL_FORMAT = "sliders-forecaster-4"
#: the shipped model's file name inside the package's data folder
DEFAULT_MODEL_NAME = "default_forecaster.zip"
#: the shipped posterior of the pile's parameters (``infer``), a model file of one entry
DEFAULT_POSTERIOR_NAME = "default_posterior.zip"
#: the bounds of a model file (the shipped one: 3.4 MB, 8 members, 12 MB inflated)
MAX_MODEL_BYTES = 64 * 2**20
MAX_MEMBERS = 100_000
MAX_MEMBER_BYTES = 64 * 2**20
MAX_INFLATED_BYTES = 256 * 2**20
#: the most bytes of the JSON tree (the shipped model's: 0.5 MB); a larger tree would cost
#: gigabytes of Python objects before anything could be checked
MAX_TREE_BYTES = 16 * 2**20
#: the SHA-256 of the shipped model, in a file beside it
DIGEST_SUFFIX = ".sha256"
#: every class or function a model file may name: the package's forecasters and the
#: scikit-learn, crepes and NumPy parts they hold, and the functions that make those parts
#: as ``pickle`` makes them (``io.model_archive``)
ALLOWED_NAMES = frozenset({
    "copyreg.__newobj__",
    "crepes.base.ConformalPredictiveSystem",
    "numpy.random._generator.Generator",
    "numpy.random._pcg64.PCG64",
    "numpy.random._pickle.__bit_generator_ctor",
    "numpy.random._pickle.__generator_ctor",
    "numpy.random.bit_generator.SeedSequence",
    "numpy.random.bit_generator.__pyx_unpickle_SeedSequence",
    "sklearn._loss._loss.CyPinballLoss",
    "sklearn._loss.link.IdentityLink",
    "sklearn._loss.link.Interval",
    "sklearn._loss.loss.PinballLoss",
    "sklearn.ensemble._hist_gradient_boosting.binning._BinMapper",
    "sklearn.ensemble._hist_gradient_boosting.gradient_boosting.HistGradientBoostingRegressor",
    "sklearn.ensemble._hist_gradient_boosting.predictor.TreePredictor",
    "sklearn.impute._base.SimpleImputer",
    "sklearn.metrics._dist_metrics.EuclideanDistance64",
    "sklearn.metrics._dist_metrics.newObj",
    "sklearn.neighbors._ball_tree.BallTree",
    "sklearn.neighbors._ball_tree.newObj",
    "sklearn.neighbors._kd_tree.KDTree",
    "sklearn.neighbors._kd_tree.newObj",
    "sklearn.neighbors._lof.LocalOutlierFactor",
    "sklearn.pipeline.Pipeline",
    "sklearn.preprocessing._data.QuantileTransformer",
    "sklearn.preprocessing._data.StandardScaler",
    "sliders.analysis.forecast.baselines.Climatology",
    "sliders.analysis.forecast.baselines.ConditionedClimatology",
    "sliders.analysis.forecast.domain.DomainCheck",
    "sliders.analysis.forecast.inverse_rate.LinearInverseRate",
    "sliders.analysis.forecast.inverse_rate.PointProcessInverseRate",
    "sliders.analysis.forecast.learned.Learned",
    "sliders.analysis.forecast.physics.ModelBased",
    "sliders.analysis.forecast.posterior.ParameterPosterior",
})


class ModelFileError(ValueError):
    """A model file that cannot be used: one line naming the file."""


def default_model_path() -> pathlib.Path:
    """The shipped default model: a ``pathlib.Path`` inside the installed package.

    Found with ``importlib.resources``; meson-python's editable install answers
    with a traversable of its own rather than a path, and there the file is
    the one beside this module's package (``sliders/data/``), the same place.
    """
    return shipped_path(DEFAULT_MODEL_NAME)


def default_posterior_path() -> pathlib.Path:
    """The shipped posterior of the pile's parameters (``infer``), beside the default model."""
    return shipped_path(DEFAULT_POSTERIOR_NAME)


def shipped_path(name: str) -> pathlib.Path:
    """The file ``name`` of the package's data folder (``default_model_path``)."""
    found = importlib.resources.files("sliders").joinpath("data", name)
    if isinstance(found, pathlib.Path):
        return found
    return pathlib.Path(__file__).resolve().parent.parent / "data" / name


def forecasters_bytes(forecasters: dict, provenance: dict, where: str = "model") -> bytes:
    """The model file's bytes for fitted forecasters (``{method: forecaster}``) and their provenance.

    Checked as ``load_forecasters`` reads it, so that a model naming a type
    off the allow-list is never written.
    """
    try:
        blob = model_archive.dumps({"format": MODEL_FORMAT, "forecasters": dict(forecasters),
                                    "provenance": dict(provenance)}, ALLOWED_NAMES)
    except model_archive.ArchiveError as exc:
        raise ModelFileError(f"{printable(where)}: not written: {exc}") from None
    _loads(blob, where)
    return blob


def save_forecasters(path: str, forecasters: dict, provenance: dict) -> int:
    """Write a model file atomically (``forecasters_bytes``); returns its size in bytes."""
    blob = forecasters_bytes(forecasters, provenance, path)
    publish_bytes(path, blob, overwrite=True)
    return len(blob)


def _loads(blob: bytes, where):
    """The object of a model archive, built only if every class or function it names is on
    ``ALLOWED_NAMES`` (the whole tree is read before anything is imported or built)."""
    with no_imports_from_the_current_folder():
        return _loads_here(blob, where)


def _loads_here(blob: bytes, where):
    try:
        return model_archive.loads(blob, ALLOWED_NAMES)
    except model_archive.UntrustedNames as exc:
        refused = [printable(n) for n in exc.names]
        raise ModelFileError(f"{where}: refused: the file names types that are not on the "
                             f"allow-list of forecaster files ({', '.join(refused[:3])}"
                             f"{', ...' if len(refused) > 3 else ''}); nothing was loaded") \
            from None
    except zipfile.BadZipFile as exc:  # a member's CRC-32 or its header does not match
        raise ModelFileError(f"{where}: damaged model file ({exc})") from None
    except MemoryError:
        raise ModelFileError(f"{where}: damaged model file (out of memory while reading it)") \
            from None
    except model_archive.ArchiveError as exc:
        raise ModelFileError(f"{where}: damaged model file ({printable(str(exc))})") from None
    except Exception as exc:  # noqa: BLE001 (whatever the archive holds: it is not a model file)
        raise ModelFileError(f"{where}: damaged model file ({type(exc).__name__})") from None


@contextlib.contextmanager
def no_imports_from_the_current_folder():
    """Within: no module is imported from the current folder or the running script's.

    Reading a model file imports the modules of the classes it names (all on the
    allow-list), and a module imported then may import others by names of its own (scipy's
    Cython shadows do, wherever Cython is installed): ``./exp2.py`` or ``./gamma.py``
    (scipy.special's names) would then run while a model file is read.  The folders leave
    ``sys.path`` for that time.
    """
    mine = {os.getcwd()}
    if sys.argv and sys.argv[0] not in ("", "-c", "-m"):
        mine.add(os.path.dirname(os.path.abspath(sys.argv[0])))
    saved = list(sys.path)
    sys.path[:] = [p for p in saved if os.path.abspath(p or os.curdir) not in mine]
    try:
        yield
    finally:
        sys.path[:] = saved


def read_model_bytes(path) -> bytes:
    """The bytes of a model file: a regular file of at most ``MAX_MODEL_BYTES``, read once
    through one open descriptor (a device, a fifo, a folder or a larger file is refused from
    its status, before a byte is read)."""
    where = printable(path)
    try:
        with open(path, "rb") as fh:
            st = os.fstat(fh.fileno())
            if not stat.S_ISREG(st.st_mode):
                raise ModelFileError(f"{where}: not a regular file (a model file is a zip "
                                     "archive on disk)")
            if st.st_size > MAX_MODEL_BYTES:
                raise ModelFileError(f"{where}: {st.st_size / 2**20:.0f} MB; a model file holds "
                                     f"at most {MAX_MODEL_BYTES // 2**20} MB")
            blob = fh.read(MAX_MODEL_BYTES + 1)
    except IsADirectoryError:
        raise ModelFileError(f"{where}: a folder, not a model file") from None
    except OSError as exc:
        raise ModelFileError(f"{where}: {exc.strerror or exc}") from None
    if len(blob) > MAX_MODEL_BYTES:  # grew while read
        raise ModelFileError(f"{where}: more than {MAX_MODEL_BYTES // 2**20} MB")
    return blob


def check_archive(blob: bytes, where) -> None:
    """The zip's members bounded before any is inflated: their number, each one's declared
    size and their total (``zipfile`` inflates no more than a member declares); every NumPy
    member's header read, its array numeric and of exactly the size its member declares."""
    where = printable(where)
    try:
        archive = zipfile.ZipFile(io.BytesIO(blob))
        infos = archive.infolist()
    except (zipfile.BadZipFile, ValueError, OSError, EOFError):
        raise ModelFileError(f"{where}: refused: not a sliders model file (a zip of fitted "
                             "objects; a pickle is never loaded)") from None
    if len(infos) > MAX_MEMBERS:
        raise ModelFileError(f"{where}: {len(infos)} members; a model file holds at most "
                             f"{MAX_MEMBERS}")
    big = max(infos, key=lambda i: i.file_size, default=None)
    if big is not None and big.file_size > MAX_MEMBER_BYTES:
        raise ModelFileError(f"{where}: member {printable(big.filename)!r} inflates to "
                             f"{big.file_size / 2**20:.0f} MB; a member holds at most "
                             f"{MAX_MEMBER_BYTES // 2**20} MB")
    total = sum(i.file_size for i in infos)
    if total > MAX_INFLATED_BYTES:
        raise ModelFileError(f"{where}: its members inflate to {total / 2**20:.0f} MB; a model "
                             f"file holds at most {MAX_INFLATED_BYTES // 2**20} MB")
    tree = next((i for i in infos if i.filename == model_archive.TREE_MEMBER), None)
    if tree is None:
        raise ModelFileError(f"{where}: not a sliders model file of format {MODEL_FORMAT} "
                             f"(it holds no {model_archive.TREE_MEMBER}): train it again")
    if tree.file_size > MAX_TREE_BYTES:
        raise ModelFileError(f"{where}: its tree inflates to {tree.file_size / 2**20:.0f} MB; a "
                             f"model file's tree holds at most {MAX_TREE_BYTES // 2**20} MB")
    for info in infos:
        if not info.filename.endswith(".npy"):
            continue
        try:
            with archive.open(info) as fh:
                version = np.lib.format.read_magic(fh)
                read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                               else np.lib.format.read_array_header_2_0)
                shape, _, dtype = read_header(fh)
                header = fh.tell()
        except Exception:  # noqa: BLE001 (a damaged member, a header NumPy cannot read)
            raise ModelFileError(f"{where}: member {printable(info.filename)!r} is not a NumPy "
                                 "array") from None
        if dtype.hasobject or dtype.kind not in "biufV" or (dtype.kind == "V" and not dtype.fields):
            raise ModelFileError(f"{where}: member {printable(info.filename)!r} holds an array "
                                 f"of dtype {printable(dtype)}, not numbers")
        size = dtype.itemsize * math.prod(shape)
        if header + size != info.file_size:
            raise ModelFileError(f"{where}: member {printable(info.filename)!r} declares an "
                                 f"array of {size} bytes in {info.file_size - header}")


def check_digest(path, blob: bytes) -> None:
    """The shipped model's bytes against the SHA-256 stored beside it (``DIGEST_SUFFIX``)."""
    recorded = pathlib.Path(str(path) + DIGEST_SUFFIX)
    try:
        expected = recorded.read_text(encoding="ascii").split()[0]
    except (OSError, UnicodeDecodeError, IndexError):
        raise ModelFileError(f"{printable(path)}: the shipped model's digest "
                             f"({recorded.name}) is missing; reinstall sliders") from None
    if hashlib.sha256(blob).hexdigest() != expected:
        raise ModelFileError(f"{printable(path)}: not the model shipped with this version (its "
                             "SHA-256 differs from the one recorded beside it); reinstall sliders")


def printable_tree(value):
    """``value`` (a provenance: dicts, lists, strings, numbers) with every string made printable."""
    if isinstance(value, dict):
        return {printable(k): printable_tree(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [printable_tree(v) for v in value]
    if isinstance(value, str):
        return printable(value)
    return value


#: the columns of a forecaster's expected-accuracy table (``expected_accuracy_``, written by
#: ``analysis.forecast.evaluation.accuracy_table``, printed by ``predict``): one value per bin
#: of ``lead_edges_deg``, and the same over every held-out cut in ``overall`` (with ``rows``)
ACCURACY_COLUMNS = ("median_abs_deg", "coverage", "n")
#: the most bins of lead an expected-accuracy table may hold
MAX_ACCURACY_BINS = 1000


def check_accuracy_table(table) -> None:
    """A forecaster's expected-accuracy table (None or empty: it holds none) as ``predict``
    reads it, else ``ValueError`` saying what is wrong: every column present, one value per
    lead bin, the lead edges finite, from 0 up and increasing, the errors finite degrees in
    [0, 90], the coverages shares in [0, 1], the counts whole numbers from 0."""
    if table is None or (isinstance(table, dict) and not table):
        return
    if not isinstance(table, dict):
        raise ValueError(f"a {type(table).__name__}, not a table of columns")
    overall = table.get("overall")
    missing = [c for c in ("lead_edges_deg", *ACCURACY_COLUMNS) if c not in table]
    missing += [] if isinstance(overall, dict) else ["overall"]
    missing += [f"overall {c}" for c in (*ACCURACY_COLUMNS, "rows")
                if isinstance(overall, dict) and c not in overall]
    if missing:
        raise ValueError(f"no column {', '.join(missing)}")
    edges = _numbers(table["lead_edges_deg"], "lead_edges_deg")
    if not 1 <= edges.size <= MAX_ACCURACY_BINS or edges[0] < 0 or (np.diff(edges) <= 0).any():
        raise ValueError(f"lead_edges_deg: {edges.size} edges, not 1 to {MAX_ACCURACY_BINS} "
                         "increasing from 0 up")
    for c in ACCURACY_COLUMNS:
        v = _numbers(table[c], c)
        if v.shape != edges.shape:
            raise ValueError(f"{c}: {v.size} values for {edges.size} lead bins")
        _in_range(v, c, c)
    for c in (*ACCURACY_COLUMNS, "rows"):
        _in_range(_numbers([overall[c]], f"overall {c}"), f"overall {c}", c)


def _numbers(values, what: str) -> np.ndarray:
    """``values`` (a list of plain numbers, or a 1-D array) as finite floats."""
    ok = isinstance(values, (list, tuple)) and all(
        isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
        for v in values)
    ok = ok or (isinstance(values, np.ndarray) and values.ndim == 1 and values.dtype.kind in "iuf")
    if not ok:
        raise ValueError(f"{what}: not a list of numbers")
    v = np.asarray(values, dtype=float)
    if not np.isfinite(v).all():
        raise ValueError(f"{what}: NaN or infinite values")
    return v


def _in_range(v: np.ndarray, what: str, column: str) -> None:
    """The values ``v`` of ``column`` in its range (degrees, a share, a count)."""
    lo, hi = {"median_abs_deg": (0.0, 90.0), "coverage": (0.0, 1.0)}.get(column, (0.0, np.inf))
    if (v < lo).any() or (v > hi).any():
        raise ValueError(f"{what}: values outside [{lo:g}, {hi:g}]" if np.isfinite(hi)
                         else f"{what}: negative values")
    if column in ("n", "rows") and (v != np.round(v)).any():
        raise ValueError(f"{what}: counts that are not whole numbers")


def check_forecasters(forecasters: dict, where, version="?") -> None:
    """Every forecaster's ``check_fitted`` (every part a forecast reads) and its expected-accuracy
    table (``check_accuracy_table``), in one line on the first that fails."""
    where = printable(where)
    for method, f in forecasters.items():
        check = getattr(f, "check_fitted", None)
        if not isinstance(method, str) or check is None:
            raise ModelFileError(f"{where}: {printable(repr(method))} holds a "
                                 f"{type(f).__name__}, not the fitted forecasters a model file holds")
        try:
            check()
        except (ValueError, AttributeError, TypeError, KeyError, IndexError) as exc:
            what = (f"a part is missing ({exc}): written by sliders {version}, whose "
                    "forecasters this version cannot use; train it again"
                    if isinstance(exc, AttributeError) else " ".join(str(exc).split()))
            raise ModelFileError(f"{where}: forecaster {printable(method)!r}: "
                                 f"{printable(what)}; refused") from None
        try:
            check_accuracy_table(getattr(f, "expected_accuracy_", None))
        except ValueError as exc:
            raise ModelFileError(f"{where}: forecaster {printable(method)!r}: its expected-"
                                 f"accuracy table: {printable(str(exc))}; refused") from None


def load_forecasters(path) -> tuple[dict, dict]:
    """The forecasters and the provenance of a model file; ``ModelFileError`` in one line.

    Nothing in the file runs, and nothing it holds is used unchecked (module
    docstring): its size, its members' sizes and arrays, the types it names
    (``ALLOWED_NAMES``) before anything is built, then every
    forecaster's parts (``check_forecasters``).  The shipped model is also
    checked by its digest.
    """
    blob = read_model_bytes(path)
    where = printable(path)
    if pathlib.Path(path).resolve() in (default_model_path().resolve(),
                                        default_posterior_path().resolve()):
        # the bytes whose archive the test suite checks (tests/test_trust_model_file.py): the
        # digest stands for the member-by-member check, a third of a cold forecast's load
        check_digest(path, blob)
    else:
        if not zipfile.is_zipfile(io.BytesIO(blob)):
            raise ModelFileError(f"{where}: refused: not a sliders model file (a zip of fitted "
                                 "objects; a pickle is never loaded)")
        check_archive(blob, path)
    obj = _loads(blob, where)
    if isinstance(obj, dict) and str(obj.get("format", "")).startswith("sliders-forecaster-") \
            and obj["format"] != MODEL_FORMAT:
        raise ModelFileError(f"{where}: a model file of format {printable(obj['format'])}; this "
                             f"version reads {MODEL_FORMAT}: train it again")
    if not isinstance(obj, dict) or obj.get("format") != MODEL_FORMAT:
        raise ModelFileError(f"{where}: not a sliders model file of format {MODEL_FORMAT}")
    forecasters, prov = obj.get("forecasters"), obj.get("provenance")
    if not isinstance(forecasters, dict) or not isinstance(prov, dict):
        raise ModelFileError(f"{where}: not a sliders model file of format {MODEL_FORMAT}")
    check_forecasters(forecasters, path, prov.get("sliders", "?"))
    return forecasters, printable_tree(prov)
