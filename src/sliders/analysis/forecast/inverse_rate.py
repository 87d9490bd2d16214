"""The failure forecast method: the rate of events (or of displacement) diverges at ``alpha_c``.

The rate law ``rate(alpha) = k (alpha_c - alpha)^(-p)`` (Voight 1988; p = 1 is
Fukuzono's 1985 linear inverse rate) is fitted to the events seen, in two ways:

* ``LinearInverseRate``: the classic least-squares fit of the inverse rate,
  measured over blocks of ``block`` events, against the tilt: a straight line
  whose zero is ``alpha_c`` (p = 1), or Voight's form with a fitted exponent
  (least squares of log inverse rate = c + p log(alpha_c - alpha)).
* ``PointProcessInverseRate``: the maximum-likelihood fit of the same law as
  an inhomogeneous Poisson process (Bell, Naylor & Main 2013), the quiet
  stretch since the last event included (the integral of the rate runs to
  the tilt reached).  For the displacement rate each event is weighted by its
  displacement (normalised to a mean weight of one: a quasi-likelihood).

Both are profiled over a grid of the remaining angle ``alpha_c - tilt_now``
(logarithmic, ``REMAINING_GRID``); the normalised likelihood on that grid is the
predictive distribution.  A fit whose best ``alpha_c`` lies at the grid's far
end sees no acceleration: it gives no forecast of its own and falls back on
the conditioned climatology (counted as ``fallback``).
"""

from __future__ import annotations

import numpy as np

from .base import Forecaster, quantiles_of_grid
from .baselines import Climatology, conditioned_quantiles
from .integrity import Spec

#: remaining angle alpha_c - tilt_now (radians) over which the fits are profiled
REMAINING_GRID = np.geomspace(1e-4, 1.0, 161)
#: exponents p of the rate law tried when the exponent is fitted
EXPONENT_GRID = np.round(np.arange(0.3, 3.01, 0.1), 2)
#: fewest events in the fitting window
MIN_EVENTS = 10


def fit_window(alpha: np.ndarray, tilt_now: float, fraction: float) -> tuple[np.ndarray, float]:
    """The events in the last ``fraction`` of the tilt range seen (first event to now): mask, start."""
    if alpha.size == 0:
        return np.zeros(0, bool), tilt_now
    start = alpha[0] + (1.0 - fraction) * (tilt_now - alpha[0])
    return alpha >= start, start


def inverse_rate_points(alpha, weight, block: int) -> tuple[np.ndarray, np.ndarray]:
    """Inverse rate over consecutive blocks of ``block`` events: (angle of the block, inverse rate).

    The inverse rate of a block is its angular span over the summed weight of
    its events after the first (weight 1: events; displacement: displacement).
    """
    nb = (alpha.size - 1) // block
    if nb < 1:
        return np.zeros(0), np.zeros(0)
    idx = np.arange(nb) * block
    span = alpha[idx + block] - alpha[idx]
    cw = np.concatenate([[0.0], np.cumsum(weight)])
    w = cw[idx + block + 1] - cw[idx + 1]
    x = 0.5 * (alpha[idx + block] + alpha[idx])
    ok = (span > 0) & (w > 0)
    return x[ok], span[ok] / w[ok]


def linear_profile(x, y, tilt_now, exponent) -> np.ndarray:
    """Gaussian log-likelihood profile over ``REMAINING_GRID`` of the inverse-rate fit.

    exponent 1: y = b (alpha_c - x), least squares in y (Fukuzono).
    exponent None: log y = c + p log(alpha_c - x), p fitted (Voight's form).
    """
    z = (tilt_now + REMAINING_GRID)[:, None] - x[None, :]
    n = x.size
    if exponent == 1:
        b = (z @ y) / np.einsum("ij,ij->i", z, z)
        sse = np.sum((y[None, :] - b[:, None] * z) ** 2, axis=1)
    else:
        lz = np.log(z)
        ly = np.log(y)
        lzm = lz.mean(axis=1, keepdims=True)
        dz = lz - lzm
        slope = (dz @ (ly - ly.mean())) / np.einsum("ij,ij->i", dz, dz)
        resid = (ly - ly.mean())[None, :] - slope[:, None] * dz
        sse = np.sum(resid ** 2, axis=1)
        sse = np.where(slope > 0, sse, np.inf)  # inverse rate must fall towards alpha_c
    return -0.5 * n * np.log(np.maximum(sse, 1e-300))


def point_process_profile(alpha, weight, start, tilt_now, exponent) -> np.ndarray:
    """Poisson-process log-likelihood of the rate k (alpha_c - alpha)^(-p), k and p profiled out.

    Events ``alpha`` (weights ``weight``, mean 1) observed on [start, tilt_now];
    log L = sum w_i log(rate(alpha_i)) - integral of the rate, with
    k = sum w / integral at its maximum.
    """
    ac = (tilt_now + REMAINING_GRID)[:, None]
    w = np.asarray(weight, dtype=float)
    wsum = w.sum()
    slog = np.log(ac - alpha[None, :]) @ w  # (G,)
    a = np.log(ac[:, 0] - start)
    b = np.log(REMAINING_GRID)
    ps = np.array([1.0]) if exponent == 1 else EXPONENT_GRID
    best = np.full(REMAINING_GRID.size, -np.inf)
    for p in ps:
        if p == 1.0:
            integral = a - b
        else:
            integral = (np.exp((1 - p) * a) - np.exp((1 - p) * b)) / (1 - p)
        ll = wsum * np.log(wsum / integral) - wsum - p * slog
        best = np.maximum(best, ll)
    return best


class _InverseRate(Forecaster):
    """Shared parts: the climatology to fall back on, and the per-catalogue loop."""

    FIELDS = {"rate": Spec("choice", of=("events", "displacement")),
              "exponent": Spec("choice", of=(1, None)),
              "fraction": Spec("number", lo=1e-6, hi=1.0), "block": Spec("int", lo=1, hi=10_000),
              "climatology_": Spec("part", of=Climatology)}

    def __init__(self, rate: str = "events", exponent=1, fraction: float = 0.5, block: int = 5):
        self.rate = rate
        self.exponent = exponent
        self.fraction = fraction
        self.block = block

    @property
    def name(self) -> str:
        """e.g. ``ffm_ml_event``, ``ffm_linear_disp_p`` (exponent fitted)."""
        return f"{self.kind}_{'event' if self.rate == 'events' else 'disp'}" + (
            "" if self.exponent == 1 else "_p")

    @property
    def label(self) -> str:
        """The forecaster's name in tables and legends."""
        return (f"inverse rate {self.label_kind}, "
                f"{'events' if self.rate == 'events' else 'displacement'}"
                + ("" if self.exponent == 1 else " (p fitted)"))

    def fit(self, train, y=None):
        """Keep the prior's avalanche angles to fall back on where no acceleration is seen."""
        if self.rate not in ("events", "displacement"):
            raise ValueError(f"rate={self.rate!r} must be 'events' or 'displacement'")
        self.climatology_ = Climatology().fit(train)
        return self

    def _profile(self, cat):
        raise NotImplementedError

    def best_log_remaining(self, cat) -> float:
        """log of the most likely remaining angle ``alpha_c - tilt_now`` (NaN: no fit, or none in reach)."""
        ll = self._profile(cat)
        if ll is None or not np.isfinite(ll).any():
            return np.nan
        k = int(np.nanargmax(ll))
        return float(np.log(REMAINING_GRID[k])) if k < REMAINING_GRID.size - 3 else np.nan

    def _quantiles(self, cuts):
        t = cuts.tilt_now
        q, _ = conditioned_quantiles(self.climatology_.alpha_c_, t)
        fb = np.ones(len(cuts), bool)
        grid = np.log(REMAINING_GRID)
        for i, cat in enumerate(cuts.catalogues):
            ll = self._profile(cat)
            if ll is None or not np.isfinite(ll).any():
                continue
            if int(np.nanargmax(ll)) >= REMAINING_GRID.size - 3:
                continue  # best at the far end: no acceleration seen
            qi = t[i] + np.exp(quantiles_of_grid(grid, ll))
            if np.isfinite(qi).all():  # a degenerate catalogue (every event at one angle): none
                q[i], fb[i] = qi, False
        return q, fb

    def _window(self, cat):
        """The events fitted: their angles, weights (mean 1) and the window's start; None if too few."""
        sel, start = fit_window(cat.alpha, cat.tilt_now, self.fraction)
        if sel.sum() < MIN_EVENTS:
            return None
        if self.rate == "events":
            w = np.ones(int(sel.sum()))
        else:
            d = cat.displacement[sel]
            if not d.mean() > 0:
                return None
            w = d / d.mean()
        return cat.alpha[sel], w, min(start, float(cat.alpha[sel][0]))


class LinearInverseRate(_InverseRate):
    """Least-squares fit of the inverse rate against the tilt (Fukuzono; Voight with exponent).

    Parameters
    ----------
    rate : {"events", "displacement"}
        The rate of events, or of displacement, per unit tilt.
    exponent : 1 or None
        1: the straight line of Fukuzono; None: Voight's exponent fitted.
    fraction : float
        The fit uses the events in this last fraction of the tilt range seen.
    block : int
        Events per inverse-rate point.
    """

    kind, label_kind = "ffm_linear", "LSQ"

    def _profile(self, cat):
        window = self._window(cat)
        if window is None:
            return None
        x, y = inverse_rate_points(window[0], window[1], self.block)
        return linear_profile(x, y, cat.tilt_now, self.exponent) if x.size >= 3 else None


class PointProcessInverseRate(_InverseRate):
    """Maximum-likelihood fit of the rate law as a point process (Bell, Naylor & Main 2013).

    Parameters as ``LinearInverseRate`` (``block`` unused).
    """

    kind, label_kind = "ffm_ml", "ML"

    def _profile(self, cat):
        window = self._window(cat)
        return None if window is None else point_process_profile(*window, cat.tilt_now, self.exponent)
