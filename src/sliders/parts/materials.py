"""The material parameters a pile's posterior infers, one record each.

Every reader takes its names, scales, units and labels from ``MATERIALS``: the prior
specification (what may be drawn, what is derived), the posterior (its parameters, those
learned as log10), ``infer``'s text and JSON, the corner plot and the predictive check's
scenes.  A new material parameter is one more record here (and, if the scene does not
know it yet, its part).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Material:
    """One material parameter.

    Parameters
    ----------
    name : str
        The posterior's and the prior file's name.
    scale : {"log", "linear"}
        Learned as log10 (and drawn on a log axis), or as it is.
    unit : str
        Its unit (``"1"``: a number).
    label : str
        Its name in ``infer``'s text.
    axis_label : str
        Its corner plot axis.
    scene_key : str, optional
        The scene field it sets (None: it is derived, see ``derived``).
    derived : str, optional
        The scene field it gives through ``scene_values`` (None: it is a scene field).
    physical_range : tuple of float
        (low, high), the values a posterior file may hold of it: a friction coefficient of
        1000 is a tilt of 89.94 degrees, and a pile of more means nothing.
    integer : bool
        Whether a scene takes it as an integer.
    """

    name: str
    scale: str
    unit: str
    label: str
    axis_label: str
    scene_key: str | None = None
    derived: str | None = None
    physical_range: tuple[float, float] = (0.0, 1e3)
    integer: bool = False

    @property
    def log(self) -> bool:
        """Learned as log10, drawn on a log axis."""
        return self.scale == "log"


#: the gap mu_s_mean - mu_d, drawn instead of mu_s_mean (it keeps mu_s above mu_d)
MU_S_GAP = "mu_s_minus_mu_d"
#: the material parameters inferred, in the posterior's order
MATERIALS = (
    Material("mu_d", "linear", "1", "mu_d", "atan(mu_d) [deg]", scene_key="mu_d"),
    Material(MU_S_GAP, "log", "1", "mu_s - mu_d", "mu_s - mu_d", derived="mu_s_mean"),
    Material("sigma_mu", "log", "1", "sigma_mu", "sigma_mu", scene_key="sigma_mu"),
    Material("xi", "log", "1", "xi", "xi [units of k]", scene_key="xi",
             physical_range=(0.0, 1e6)),
    Material("n_sliders", "log", "1", "N (sliders)", "N (sliders)", scene_key="n_sliders",
             physical_range=(2.0, 1e12), integer=True),
)
#: the records by name
BY_NAME = {m.name: m for m in MATERIALS}
#: their names, in order
NAMES = tuple(m.name for m in MATERIALS)
#: those learned as log10 (their priors are log-uniform, or a choice spread over decades)
LOG_NAMES = tuple(m.name for m in MATERIALS if m.log)
#: drawn name -> the scene field it gives
DERIVED = {m.name: m.derived for m in MATERIALS if m.derived}


def mu_s_mean(mu_d, mu_s_minus_mu_d):
    """The mean static coefficient of a pile drawn as mu_d and mu_s - mu_d."""
    return mu_d + mu_s_minus_mu_d


def derive(name: str, values: dict):
    """The scene field ``BY_NAME[name].derived`` of the values ``values`` (name -> value or
    array): mu_s_mean from mu_d and the gap."""
    if name != MU_S_GAP:
        raise KeyError(f"{name!r} is not a derived material parameter")
    return mu_s_mean(values["mu_d"], values[MU_S_GAP])


def scene_values(values: dict) -> dict:
    """The scene fields of the material ``values`` (name -> one value, any subset of
    ``MATERIALS``; mu_s - mu_d needs mu_d): each scene field as the scene takes it."""
    out = {}
    for m in MATERIALS:
        if m.name not in values:
            continue
        v = values[m.name]
        if m.derived:
            out[m.derived] = float(derive(m.name, {"mu_d": float(values["mu_d"]),
                                                   m.name: float(v)}))
        else:
            out[m.scene_key] = int(v) if m.integer else float(v)
    return out
