"""The material parameters are defined once (``parts.materials``): the prior, the posterior,
``infer``, the corner plot and the predictive check read their records; and a catalogue is
kept to its angles and sizes by ``Catalogue.angles_and_sizes`` alone."""

from __future__ import annotations

import ast
import pathlib

import numpy as np

import sliders
from sliders.analysis.forecast import posterior
from sliders.analysis.forecast.measurement import PERFECT
from sliders.analysis.forecast.posterior_check import simulate_piles
from sliders.figures import posterior as corner
from sliders.forecasting import infer
from sliders.io.catalogue import Catalogue
from sliders.parts import materials
from sliders.runs import prior_spec
from sliders.scene import Scene

PACKAGE = pathlib.Path(sliders.__file__).parent
ROOT = PACKAGE.parent.parent


def _constants(path: pathlib.Path, value: str) -> list[int]:
    """Lines of ``path`` holding the string constant ``value`` (docstrings and messages are
    longer strings and do not count)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return [n.lineno for n in ast.walk(tree) if isinstance(n, ast.Constant) and n.value == value]


def test_the_gap_is_named_only_by_its_record():
    """A second definition of the material parameters (a list of names, a label table, the sum
    mu_d + mu_s_minus_mu_d) names the gap outside ``parts/materials.py``."""
    files = [*PACKAGE.rglob("*.py"), *(ROOT / "benchmarks").glob("*.py")]
    found = {str(p.relative_to(ROOT)): lines for p in files
             if p.name != "materials.py" and (lines := _constants(p, materials.MU_S_GAP))}
    assert found == {}


def _zeroed_catalogues(path: pathlib.Path) -> list[int]:
    """Lines of ``path`` building a ``Catalogue`` whose displacements are ``zeros(...)``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    name = lambda f: getattr(f, "attr", getattr(f, "id", None))  # noqa: E731
    return [n.lineno for n in ast.walk(tree)
            if isinstance(n, ast.Call) and name(n.func) == "Catalogue" and len(n.args) > 2
            and isinstance(n.args[2], ast.Call) and name(n.args[2].func) == "zeros"]


def test_no_copy_of_a_catalogue_kept_to_its_angles_and_sizes():
    """Only ``Catalogue.angles_and_sizes`` builds a catalogue of its angles and sizes (zero
    displacements, unknown movers)."""
    files = [*PACKAGE.rglob("*.py"), *(ROOT / "benchmarks").glob("*.py")]
    found = {str(p.relative_to(ROOT)): lines for p in files
             if p != PACKAGE / "io" / "catalogue.py" and (lines := _zeroed_catalogues(p))}
    assert found == {}


def test_every_reader_lists_the_records():
    names = [m.name for m in materials.MATERIALS]
    logs = [m.name for m in materials.MATERIALS if m.scale == "log"]
    assert list(posterior.POSTERIOR_PARAMETERS) == names
    assert list(posterior.LOG_PARAMETERS) == logs
    assert list(posterior.PHYSICAL_RANGES) == names
    assert list(infer.LABELS) == names and list(corner.AXIS_LABELS) == names
    assert list(corner.LOG_AXES) == logs
    assert set(names) <= set(prior_spec.DRAWABLE)
    assert prior_spec.DERIVED == {materials.MU_S_GAP: "mu_s_mean"}
    assert {m.scale for m in materials.MATERIALS} <= {"log", "linear"}
    assert all((m.scene_key is None) != (m.derived is None) for m in materials.MATERIALS)


def test_the_predictive_check_builds_its_scenes_from_the_records():
    """Each draw's pile has the drawn material: mu_s_mean = mu_d + the gap, N whole."""
    seen = []

    def run_pile(scene):
        seen.append(scene)
        return sliders.tilt(scene)

    material = {"mu_d": np.array([0.4, 0.5]), materials.MU_S_GAP: np.array([0.05, 0.1]),
                "sigma_mu": np.array([0.01, 0.02]), "xi": np.array([0.0, 1e-3]),
                "n_sliders": np.array([6.0, 8.0])}
    cats, _ = simulate_piles(Scene(n_sliders=5, mode="explore"), run_pile, material, 0.3,
                             PERFECT, np.random.default_rng(0))
    assert len(cats) == 2 and all(c.tilt_now >= 0.3 for c in cats)
    assert [s.n_sliders for s in seen] == [6, 8]
    assert np.allclose([s.mu_s_mean for s in seen], [0.45, 0.6])
    assert np.allclose([s.sigma_mu for s in seen], [0.01, 0.02])
    assert [s.xi for s in seen] == [0.0, 1e-3]


def test_a_catalogue_kept_to_its_angles_and_sizes():
    cat = Catalogue([0.1, 0.2], [1, 3], [0.5, 1.5], [0, 2], [0, 4], tilt_now=0.25)
    assert cat.complete
    kept = cat.angles_and_sizes()
    assert not kept.complete
    assert np.array_equal(kept.alpha, cat.alpha) and np.array_equal(kept.size, cat.size)
    assert np.array_equal(kept.displacement, [0.0, 0.0])
    assert np.array_equal(kept.first, [-1, -1]) and np.array_equal(kept.last, [-1, -1])
    assert kept.tilt_now == 0.25
    assert not Catalogue([0.1], [1], [np.nan], [0], [0]).complete
    assert not Catalogue([0.1], [1], [0.5], [0], [-1]).complete
    assert Catalogue([], [], [], [], []).complete


def test_infer_reads_a_cameras_complete_catalogue_by_its_angles_and_sizes(shipped_model):
    """Displacements in a camera's unit are not the model's: the posterior of a camera's
    complete catalogue is that of its angles and sizes, not that of the catalogue read as
    the model's units."""
    from sliders.analysis.forecast.arrays import reference_catalogues

    full, _ = reference_catalogues()[0]
    camera = shipped_model.infer(full, check=False, displacement_unit="arbitrary").to_dict()
    kept = shipped_model.infer(full.angles_and_sizes(), check=False).to_dict()
    as_model = shipped_model.infer(full, check=False).to_dict()
    assert not camera["complete"] and as_model["complete"]
    assert camera["parameters"] == kept["parameters"] != as_model["parameters"]
