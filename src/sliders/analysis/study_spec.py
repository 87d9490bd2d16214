"""A parameter study's design: the TOML (``[study]``, ``[scene]``, ``[axes]``) parsed and validated.

Every point's scene is built before anything runs.  The runner
(``sliders.runs.study``) and the analysis (``sliders.analysis.study_analysis``)
both read a study through this module; neither needs the other.
"""

from __future__ import annotations

import difflib
import hashlib
import itertools
import json
import os
from dataclasses import dataclass, field
from typing import Any

from ..parts.checks import SceneError
from ..scene import Scene, check_memory, check_tilt_statistics, read_toml, scene_keys
from ..analysis.observables import default_grids

STUDY_PREFIX = "study_"  # extra per-realisation statistics (burst periods, synchronisation)
NOT_AXES = ("seed", "output", "record")  # seed: common random numbers; record: statistics needed


class StudyError(ValueError):
    """A bad study file or command line: one line, nothing is run."""


# ---------------------------------------------------------------------------
# the study file
# ---------------------------------------------------------------------------
@dataclass
class Study:
    """A validated study: base scene, axes, and every point's scene."""

    base: dict[str, Any]
    axes: dict[str, list]
    zipped: list[list[str]]
    realisations: int
    dims: list[list[str]] = field(default_factory=list)  # per dimension: its axis names
    points: list[dict[str, Any]] = field(default_factory=list)  # axis values per point
    scenes: list[Scene] = field(default_factory=list)

    @property
    def spec(self) -> dict[str, Any]:
        """The study as plain data: base scene, axes, zipped axes, realisations per point."""
        return {"scene": self.base, "axes": self.axes, "zip": self.zipped,
                "realisations": self.realisations}

    @property
    def digest(self) -> str:
        """A 16-hex-digit SHA-256 of ``spec``: a resumed file must carry the same one."""
        # axis order matters (it orders the points and the dimensions): no sort_keys
        return hashlib.sha256(json.dumps(self.spec).encode()).hexdigest()[:16]

    @property
    def shape(self) -> tuple[int, ...]:
        """Number of values along each dimension of the study (zipped axes share one)."""
        return tuple(len(self.axes[d[0]]) for d in self.dims)

    @property
    def base_seed(self) -> int:
        """The scene seed; realisation r uses ``realisation_seed(base_seed, r)`` at every point."""
        return int(self.scenes[0].seed)

    def cost(self, p: int) -> float:
        """Relative cost of one realisation of point p (time steps x sliders ~ N^2 / dt)."""
        s = self.scenes[p]
        return float(s.n_sliders) ** 2 / float(s.dt or 1.0)


def _hint(key: str, known) -> str:
    close = difflib.get_close_matches(key, sorted(known), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _point_text(values: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in values.items())


def _check_tables(data: dict, where: str) -> tuple[dict, dict, Any]:
    """The three tables of a study and its [study] options: ([study], [scene], [axes])."""
    for k in data:
        if k not in ("study", "scene", "axes"):
            raise StudyError(f"{where}: unknown table or key {k!r}{_hint(k, ['study', 'scene', 'axes'])}; "
                             "a study has [study], [scene] and [axes]")
    opts = data.get("study", {})
    base = data.get("scene", {})
    if not isinstance(opts, dict) or not isinstance(base, dict):
        raise StudyError(f"{where}: [study] and [scene] must be tables")
    for k in opts:
        if k not in ("realisations", "zip"):
            raise StudyError(f"{where}: unknown key {k!r} in [study]{_hint(k, ['realisations', 'zip'])}"
                             "; allowed: realisations, zip")
    R = opts.get("realisations")
    if not isinstance(R, int) or isinstance(R, bool) or R < 1:
        raise StudyError(f"{where}: [study] realisations must be an integer >= 1, got {R!r}")
    return opts, base, data.get("axes")


def _check_axes(axes: Any, base: dict, known: set[str], where: str) -> None:
    """Each axis a non-empty list of values of a scene parameter that may vary and that
    [scene] does not also fix."""
    for k in base:
        if k not in known:
            raise StudyError(f"{where}: [scene] has unknown parameter {k!r}{_hint(k, known)}")
    if not isinstance(axes, dict) or not axes:
        raise StudyError(f"{where}: an [axes] table with at least one axis is required")
    for name, values in axes.items():
        if name not in known:
            raise StudyError(f"{where}: axis {name!r} is not a scene parameter{_hint(name, known)}")
        if name in NOT_AXES:
            why = ("realisations share their seeds across points (common random numbers); vary "
                   "[study] realisations instead" if name == "seed" else
                   "every point needs its statistics (record = 'displacements' or 'forces')")
            raise StudyError(f"{where}: axis {name!r} cannot vary: {why}")
        if not isinstance(values, list):
            raise StudyError(f"{where}: axis {name!r} must be a list of values, got {values!r}")
        if not values:
            raise StudyError(f"{where}: axis {name!r} is empty (give at least one value)")
        if name in base:
            raise StudyError(f"{where}: {name!r} is both in [scene] and an axis; keep one")


def _check_zip(zipped: Any, axes: dict, where: str) -> list[list[str]]:
    """The study's dimensions: each group of zipped axes (each axis once, equal lengths) is
    one, every other axis one more, in the order the axes are written."""
    if not (isinstance(zipped, list) and all(isinstance(g, list) and len(g) >= 2 for g in zipped)):
        raise StudyError(f"{where}: [study] zip must be a list of lists of >= 2 axis names")
    seen: set[str] = set()
    for g in zipped:
        for name in g:
            if name not in axes:
                raise StudyError(f"{where}: zip names {name!r}, which is not an axis"
                                 f"{_hint(str(name), axes)}")
            if name in seen:
                raise StudyError(f"{where}: axis {name!r} is zipped twice")
            seen.add(name)
        lengths = {n: len(axes[n]) for n in g}
        if len(set(lengths.values())) != 1:
            raise StudyError(f"{where}: zipped axes need equal lengths, got {lengths}")
    dims = [list(g) for g in zipped] + [[n] for n in axes if n not in seen]
    dims.sort(key=lambda d: list(axes).index(d[0]))  # in the order the axes are written
    return dims


def _point_scene(base: dict, values: dict[str, Any], p: int, where: str) -> Scene:
    """The scene of point p (axis ``values`` over ``base``), checked for a study's statistics."""
    try:
        scene = Scene.from_dict({**base, **values})
        check_tilt_statistics(scene)
        if scene.record == "summary":
            raise SceneError("record = 'summary' keeps no statistics; a study needs "
                             "'displacements' or 'forces'")
        default_grids(scene)
    except (SceneError, ValueError, TypeError) as exc:
        text = str(exc)  # the axis the scene's message names, else the first one
        culprit = next((n for n in values if n in text), next(iter(values)))
        raise StudyError(f"{where}: axis {culprit!r} at point {p} ({_point_text(values)}): "
                         f"{' '.join(str(exc).split())}") from None
    return scene


def parse_study(data: dict, where: str = "study") -> Study:
    """Validate a study (the parsed TOML); every point's scene is built, nothing is run."""
    known = {key.name for key in scene_keys()}
    opts, base, axes = _check_tables(data, where)
    _check_axes(axes, base, known, where)
    zipped = opts.get("zip", [])
    dims = _check_zip(zipped, axes, where)
    study = Study(dict(base), {k: list(v) for k, v in axes.items()}, [list(g) for g in zipped],
                  int(opts["realisations"]), dims)
    for idx in itertools.product(*(range(len(axes[d[0]])) for d in dims)):
        values = {n: axes[n][i] for d, i in zip(dims, idx) for n in d}
        study.scenes.append(_point_scene(base, values, len(study.points), where))
        study.points.append(values)
    return study


def load_study(path, data: bytes | None = None) -> Study:
    """Read and validate a study file (TOML: ``[study]``, ``[scene]``, ``[axes]``).

    Every point's scene is built before anything runs; a bad key, an empty
    axis or a value invalid at one point raises ``StudyError`` naming the axis
    and the point.  ``data``: the file's bytes, when they were read elsewhere (MPI rank 0).
    """
    where = f"study file {os.fspath(path)!r}"
    return parse_study(read_toml(path, where, StudyError, data), where)


def check_points_memory(study: Study, ranks: int = 1) -> None:
    """Refuse (StudyError naming the point) a study with a point too large for the memory
    available, ``ranks`` such runs at once on one node: checked before anything is created."""
    for p, (values, scene) in enumerate(zip(study.points, study.scenes)):
        try:
            check_memory(scene, ranks)
        except SceneError as exc:
            raise StudyError(f"point {p} ({_point_text(values)}): "
                             f"{' '.join(str(exc).split())}") from None


def spec_difference(stored: dict[str, Any], study: Study, given: str = "the study file") -> str:
    """What differs in meaning between a stored study (``Study.spec`` as a file keeps it)
    and ``study``: "" when they are the same study, else "<part> differ: <key> is ... in
    the file, ... in <given>" for the first differing key (part: scene, axes, zip,
    realisations).  Parsed, not textual: key order, ``0`` for ``0.0``, a default written
    out or left implicit make no difference; the order of the axes does (it orders the
    points and the file's dimensions)."""
    data: dict[str, Any] = {"study": {"realisations": stored.get("realisations")},
                            "scene": stored.get("scene", {}), "axes": stored.get("axes")}
    if stored.get("zip"):
        data["study"]["zip"] = stored["zip"]
    try:
        theirs = parse_study(data, "the file's study")
    except StudyError as exc:
        return f"the file's study cannot be read by this version ({exc})"
    if theirs.realisations != study.realisations:
        return (f"realisations differ: {theirs.realisations} in the file, "
                f"{study.realisations} in {given}")
    a, b = list(theirs.axes), list(study.axes)
    for name in a + b:
        if (name in a) != (name in b):
            where = "the file" if name in a else given
            return f"axes differ: {name} is an axis only in {where}"
    if a != b:
        return (f"axes differ in order: {', '.join(a)} in the file, {', '.join(b)} in {given} "
                "(the order numbers the points)")
    zips = (sorted(sorted(g) for g in theirs.zipped), sorted(sorted(g) for g in study.zipped))
    if zips[0] != zips[1]:
        return f"zip differ: {zips[0]} in the file, {zips[1]} in {given}"
    for name in a:
        x, y = theirs.axes[name], study.axes[name]
        if len(x) != len(y) or any(u != v for u, v in zip(x, y)):
            return f"axes differ: {name} is {x} in the file, {y} in {given}"
    for sa, sb in zip(theirs.scenes, study.scenes):
        da, db = sa.to_dict(), sb.to_dict()
        for key in da:
            if da[key] != db[key]:
                return f"scene differ: {key} is {da[key]!r} in the file, {db[key]!r} in {given}"
    return ""
