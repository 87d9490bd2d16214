"""Development data of ``evaluate --dev``: a small prior ensemble run serially here.

The prior ensembles of production are ``python -m sliders.prior``'s files
(``sliders.io.prior_file``); this one draws its materials from ``DEV_PRIOR``
and runs each scene here, without a ceiling.
"""

from __future__ import annotations

import numpy as np

from ...driver import run
from ...io.catalogue import Catalogue, CatalogueSet
from ...parts.materials import MU_S_GAP, derive, scene_values
from ...scene import Scene

#: the prior ensembles' default prior (mpi_runs/priors/default.toml): name -> (law, bounds)
DEV_PRIOR = {"mu_d": ("uniform", (0.3, 0.8)), MU_S_GAP: ("loguniform", (0.02, 0.12)),
             "sigma_mu": ("uniform", (0.005, 0.03)), "xi": ("loguniform", (1e-4, 1e-2)),
             "n_sliders": ("choice", (100, 200, 400))}


def draw_dev_parameters(n: int, seed: int, prior: dict | None = None) -> dict:
    """Draw ``n`` materials from ``prior`` (default ``DEV_PRIOR``; xi = 0 with probability 1/2)."""
    rng = np.random.default_rng(seed)
    prior = DEV_PRIOR if prior is None else prior
    out = {}
    for name, (law, b) in prior.items():
        if law == "uniform":
            out[name] = rng.uniform(b[0], b[1], n)
        elif law == "loguniform":
            out[name] = np.exp(rng.uniform(np.log(b[0]), np.log(b[1]), n))
        elif law == "choice":
            out[name] = rng.choice(np.asarray(b), n)
        elif law == "point":
            out[name] = np.full(n, b)
        else:
            raise ValueError(f"unknown law {law!r} for {name}")
    if prior is DEV_PRIOR:
        out["xi"] = np.where(rng.random(n) < 0.5, 0.0, out["xi"])
    return out


def dev_catalogue_set(n: int, seed: int = 0, initial_forces: str = "uniform", mode: str = "explore",
                      prior: dict | None = None) -> CatalogueSet:
    """A small prior ensemble run serially here: development and test data, no ceiling.

    Parameters
    ----------
    n : int
        Realisations.
    seed : int
        Seeds the draws and (``seed * 100003 + row``) the scenes.
    initial_forces : {"uniform", "zero"}
        The preparation.
    mode : str
        Speed mode of the scenes.
    prior : dict, optional
        ``DEV_PRIOR``'s form.
    """
    par = draw_dev_parameters(n, seed, prior)
    cats, alpha_c, status = [], [], []
    for r in range(n):
        scene = Scene(**scene_values({name: v[r] for name, v in par.items()}),
                      seed=(seed * 100003 + r) % 2**32, initial_forces=initial_forces, mode=mode,
                      record="displacements")
        res = run(scene)
        cats.append(Catalogue.from_result(res))
        status.append(res.status)
        alpha_c.append(res.alpha_c if res.status == "avalanche" else np.nan)
    params = {"mu_d": par["mu_d"], "mu_s_mean": derive(MU_S_GAP, par),
              "sigma_mu": par["sigma_mu"], "xi": par["xi"], "n_sliders": par["n_sliders"]}
    return CatalogueSet.from_catalogues(cats, params, alpha_c, status,
                                        attrs={"source": "sliders.runs.forecast.dev.dev_catalogue_set",
                                               "seed": seed, "initial_forces": initial_forces,
                                               "mode": mode})
