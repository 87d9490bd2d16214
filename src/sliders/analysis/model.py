"""Analytical model of the paper, Sec. IV (pure NumPy + ``math``, no simulation).

Dimensionless units throughout (docs/model.md): time tau, length g tau^2, force m g, angles in radians.  Two parts:

* **A single slider** between two immobile walls (paper Sec. IV-A): event
  displacement, force drop, first-order angle increment and the exact
  sequence of rearrangement angles for a constant static coefficient.
* **Statistical point of view** (paper Sec. IV-B): the histogram of tangential
  forces in bins of width ``2 dmu`` (``dmu = mu_s_mean - mu_d``) counted down
  from ``mu_s_mean``, its master equations, their closed-form solution
  (Eq. model), the crude limit (Eq. crude), a direct RK4 integration of the
  same equations (optionally with a number of bins that decreases with the
  tilt), and the transition angle (Eqs. not_neg and cond).

Notes on the paper (see the docstrings for details):

* The printed ``P_1`` of Eq. (model) lacks a term ``1/(2 mu_s)``: as printed
  it gives ``P_1(0) = 0`` instead of the initial condition ``1/(2 mu_s)`` and
  contradicts Eq. (crude).  :func:`bin_heights` uses the corrected form,
  :func:`paper_p1` gives both.
* The text counts ``N cos(alpha) P_i d_alpha`` sliders moving between bins,
  but the master equations and their solution drop the ``cos(alpha)``
  (first order in alpha).  This module follows the equations; keeping the
  factor would amount to replacing ``alpha`` by ``sin(alpha)`` in ``x``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "single_slider_displacement",
    "single_slider_force_drop",
    "single_slider_next_increment",
    "single_slider_angles",
    "n_bins",
    "bin_heights",
    "paper_p1",
    "crude_bin_heights",
    "integrate_master_equations",
    "probability_total",
    "transition_angle_stirling",
    "transition_angle_exact",
    "transition_angle_from_p3",
]

#: Tolerance subtracted before ``ceil`` in :func:`n_bins`, so that a ratio that
#: is an integer mathematically but lands a few ulps above it in floating point
#: (e.g. ``1.2 / 0.1 = 12.000000000000002``) gives that integer.
NU_TOLERANCE = 1e-9


# --------------------------------------------------------------------------
# validation helpers
# --------------------------------------------------------------------------
def _check_friction(mu_s: float, mu_d: float, name_s: str = "mu_s_mean") -> float:
    """Validate the friction coefficients; return ``dmu = mu_s - mu_d``."""
    for name, value in ((name_s, mu_s), ("mu_d", mu_d)):
        if not np.isscalar(value) or not math.isfinite(float(value)):
            raise ValueError(f"{name} must be a finite real number, got {value!r}")
    if mu_d < 0.0:
        raise ValueError(f"mu_d must be non-negative, got {mu_d!r}")
    if mu_s <= mu_d:
        raise ValueError(
            f"{name_s} must exceed mu_d (got {name_s}={mu_s!r}, mu_d={mu_d!r})")
    return float(mu_s) - float(mu_d)


def _check_alpha(alpha: ArrayLike, name: str = "alpha") -> np.ndarray:
    """Return ``alpha`` as a float array, checked to lie in ``[0, pi/2]``."""
    a = np.asarray(alpha, dtype=float)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite (got NaN or inf)")
    if np.any(a < 0.0) or np.any(a > 0.5 * math.pi):
        raise ValueError(f"{name} must lie in [0, pi/2], got values in "
                         f"[{a.min()!r}, {a.max()!r}]")
    return a


def _check_level(level: float) -> float:
    if not (np.isscalar(level) and 0.0 < float(level) < 1.0):
        raise ValueError(f"level must lie in ]0, 1[, got {level!r}")
    return float(level)


# --------------------------------------------------------------------------
# single slider between two walls (Sec. IV-A)
# --------------------------------------------------------------------------
def single_slider_displacement(alpha: ArrayLike, mu_s: float, mu_d: float):
    """Displacement of one event, ``(mu_s - mu_d) cos(alpha)`` (Sec. IV-A).

    Parameters
    ----------
    alpha : float or array_like
        Tilt at which the slider destabilises, in ``[0, pi/2]``.
    mu_s, mu_d : float
        Static and dynamic friction coefficients, ``mu_s > mu_d >= 0``.
    """
    dmu = _check_friction(mu_s, mu_d, "mu_s")
    return dmu * np.cos(_check_alpha(alpha))


def single_slider_force_drop(alpha: ArrayLike, mu_s: float, mu_d: float):
    """Magnitude of the force drop of one event, ``2 (mu_s - mu_d) cos(alpha)``.

    The paper writes ``Delta F^(1) = -2 (mu_s - mu_d) cos(alpha^(1))``; the
    positive magnitude is returned (two wall springs of unit stiffness).
    """
    dmu = _check_friction(mu_s, mu_d, "mu_s")
    return 2.0 * dmu * np.cos(_check_alpha(alpha))


def single_slider_next_increment(alpha_i: ArrayLike, mu_s: float, mu_d: float):
    """First-order increment ``Delta alpha^(i+1) = 2 (mu_s - mu_d) / (1 + mu_s tan alpha^(i))``.

    Sec. IV-A, valid to first order in ``mu_s - mu_d`` (the exact increment,
    from :func:`single_slider_angles`, differs by ``O((mu_s - mu_d)^2)``).
    """
    dmu = _check_friction(mu_s, mu_d, "mu_s")
    a = _check_alpha(alpha_i, "alpha_i")
    return 2.0 * dmu / (1.0 + mu_s * np.tan(a))


def _destabilisation_angle(elastic_force: float, mu_s: float) -> float:
    """Root in ``[0, pi/2]`` of ``F' + sin(a) = mu_s cos(a)``.

    ``sin a - mu_s cos a = R sin(a - phi)`` with ``R = sqrt(1 + mu_s^2)``,
    ``phi = atan(mu_s)``, hence ``a = phi + asin(-F'/R)``; the left-hand side
    is increasing on ``[0, pi/2]``, so this root is the only one there.
    """
    r = math.hypot(1.0, mu_s)
    return math.atan(mu_s) + math.asin(max(-1.0, min(1.0, -elastic_force / r)))


def single_slider_angles(initial_force: float, mu_s: float, mu_d: float,
                         alpha_max: float) -> np.ndarray:
    """Exact rearrangement angles ``alpha^(i) <= alpha_max`` of a single slider.

    Sec. IV-A with ``sigma_mu = 0``.  The elastic force ``F' = F - sin(alpha)``
    is constant while the slider rests, so each threshold solves exactly
    ``F' + sin(alpha) = mu_s cos(alpha)``, i.e.
    ``alpha = atan(mu_s) + asin(-F' / sqrt(1 + mu_s^2))``.  The first
    elastic force is ``initial_force`` (the force at ``alpha = 0``); after
    an event at ``a`` the force is ``mu_s cos a - 2 (mu_s - mu_d) cos a``, so
    ``F' = (2 mu_d - mu_s) cos a - sin a``.

    Parameters
    ----------
    initial_force : float
        Tangential force at ``alpha = 0``; must be stable,
        ``|initial_force| <= mu_s``.
    mu_s, mu_d : float
        Friction coefficients, ``mu_s > mu_d >= 0``.
    alpha_max : float
        Last tilt considered, in ``[0, pi/2]``.

    Returns
    -------
    numpy.ndarray
        Increasing angles ``alpha^(1), alpha^(2), ...`` not above ``alpha_max``.
    """
    _check_friction(mu_s, mu_d, "mu_s")
    alpha_max = float(_check_alpha(alpha_max, "alpha_max"))
    if not (np.isscalar(initial_force) and math.isfinite(float(initial_force))):
        raise ValueError(f"initial_force must be a finite real number, got {initial_force!r}")
    if abs(initial_force) > mu_s:
        raise ValueError(
            f"initial_force must be stable at alpha=0, |initial_force| <= mu_s "
            f"(got initial_force={initial_force!r}, mu_s={mu_s!r})")
    angles = []
    a = _destabilisation_angle(float(initial_force), mu_s)
    while a <= alpha_max:
        angles.append(a)
        elastic = (2.0 * mu_d - mu_s) * math.cos(a) - math.sin(a)
        a = _destabilisation_angle(elastic, mu_s)
    return np.array(angles)


# --------------------------------------------------------------------------
# master equations (Sec. IV-B)
# --------------------------------------------------------------------------
def n_bins(alpha: ArrayLike, mu_s_mean: float, mu_d: float):
    """Number of bins ``nu(alpha) = ceil((2 mu_s - sin(alpha)) / (2 dmu))``.

    Bins of width ``2 dmu`` are counted down from ``mu_s_mean`` and include
    the lower bound ``sin(alpha) - mu_s_mean`` of the force distribution.
    The ceiling is taken of ``ratio - NU_TOLERANCE`` (``1e-9``) so that a
    ratio that is mathematically an integer gives that integer: for
    ``(0.6, 0.55)``, ``1.2 / 0.1`` evaluates to ``12.000000000000002`` and
    ``nu(0) = 12 = mu_s / dmu``.  At a bin edge (``sin(alpha) = 2 mu_s -
    2 dmu k``) the result is ``k``: ``nu`` drops at the edge itself (the
    tolerance moves the edges by ``2 dmu 1e-9`` in ``sin(alpha)``).

    Returns
    -------
    int or numpy.ndarray of int
    """
    dmu = _check_friction(mu_s_mean, mu_d)
    a = _check_alpha(alpha)
    nu = np.ceil((2.0 * mu_s_mean - np.sin(a)) / (2.0 * dmu) - NU_TOLERANCE).astype(int)
    if np.any(nu < 1):
        raise ValueError(
            f"alpha too large: sin(alpha) >= 2 mu_s_mean leaves no bin (alpha={alpha!r})")
    return int(nu) if nu.ndim == 0 else nu


def _bin_edges(mu_s_mean: float, mu_d: float) -> list[tuple[float, int]]:
    """Angles in ``]0, pi/2[`` where ``nu`` drops to ``k``, as ``(angle, k)``, increasing.

    ``nu(alpha) <= k`` once ``(2 mu_s - sin(alpha)) / (2 dmu) - NU_TOLERANCE <= k``,
    i.e. from ``sin(alpha) = 2 mu_s - 2 dmu (k + NU_TOLERANCE)`` on: the same
    rounding as :func:`n_bins`, so that both agree on which side of an edge
    an angle lies.
    """
    dmu = mu_s_mean - mu_d
    edges = []
    for k in range(n_bins(0.0, mu_s_mean, mu_d) - 1, 0, -1):
        s = 2.0 * mu_s_mean - 2.0 * dmu * (k + NU_TOLERANCE)
        if 0.0 < s < 1.0:
            edges.append((math.asin(s), k))
    return edges


def _poisson_terms(x: np.ndarray, kmax: int) -> np.ndarray:
    """``t_k = x^k e^{-x} / k!`` for ``k = 0..kmax``, shape ``(len(x), kmax+1)``.

    Computed in log space, ``exp(-x + k log x - lgamma(k+1))``, so that
    neither ``x^k`` nor ``k!`` is formed (no overflow, harmless underflow).
    """
    k = np.arange(kmax + 1)
    lgam = np.array([math.lgamma(j + 1.0) for j in k])
    with np.errstate(divide="ignore"):
        logx = np.log(x)[:, None]
    pos = x[:, None] > 0.0
    expo = np.where(pos, -x[:, None] + k * np.where(pos, logx, 0.0) - lgam, 0.0)
    t = np.exp(expo)
    t[~pos[:, 0], 1:] = 0.0  # x = 0: all mass in k = 0
    return t


def _resolve_nu(nu, a: np.ndarray, mu_s_mean: float, mu_d: float) -> np.ndarray:
    """Number of bins for every angle of ``a`` (1-d) according to ``nu``."""
    if nu is None or (isinstance(nu, str) and nu == "fixed"):
        return np.full(a.shape, n_bins(0.0, mu_s_mean, mu_d))
    if isinstance(nu, str) and nu == "alpha":
        return np.atleast_1d(n_bins(a, mu_s_mean, mu_d))
    if isinstance(nu, (int, np.integer)) and not isinstance(nu, bool) and nu >= 1:
        return np.full(a.shape, int(nu))
    raise ValueError(f"nu must be None, 'fixed', 'alpha' or a positive int, got {nu!r}")


def _poisson_sums(x: np.ndarray, kmax_needed: int):
    """Lower sums ``Q[:, m] = sum_{j<m} t_j`` and tails ``T[:, m] = sum_{j>=m} t_j``.

    ``Q(m, x)`` is the regularised upper incomplete gamma function,
    ``sum_{k=0}^{m-1} x^k e^{-x}/k!``; ``T = 1 - Q`` is summed from the far
    tail so that it keeps full relative precision when small.  Terms are
    kept up to ``k = x + 40 sqrt(x) + 40``; the rest is negligible in double
    precision.
    """
    xmax = float(x.max()) if x.size else 0.0
    kmax = max(kmax_needed, int(math.ceil(xmax + 40.0 * math.sqrt(xmax) + 40.0)))
    t = _poisson_terms(x, kmax)
    zero = np.zeros((x.size, 1))
    lower = np.concatenate([zero, np.cumsum(t, axis=1)], axis=1)
    tail = np.concatenate([np.cumsum(t[:, ::-1], axis=1)[:, ::-1], zero], axis=1)
    return lower, tail


def bin_heights(alpha: ArrayLike, mu_s_mean: float, mu_d: float, nu=None) -> np.ndarray:
    """Closed-form bin heights ``P_i(alpha)`` of Eq. (model), ``i = 1..nu``.

    The master equations (Sec. IV-B), with ``x = alpha / (2 dmu)``,

    ``dP_nu/dalpha = -P_nu / (2 dmu)``,
    ``dP_i/dalpha = (P_{i+1} - P_i) / (2 dmu)`` for ``1 < i < nu``,
    ``dP_1/dalpha = P_2 / (2 dmu)``,

    from ``P_i(0) = 1/(2 mu_s)`` and for a **fixed** number of bins ``nu``,
    are solved by ``P_i = Q(nu - i + 1, x) / (2 mu_s)`` for ``i >= 2``
    (``P_nu = e^{-x} / (2 mu_s)``), where
    ``Q(m, x) = sum_{k=0}^{m-1} x^k e^{-x} / k!`` is the regularised upper
    incomplete gamma function, and, since ``sum_i P_i`` is conserved,

    ``P_1 = nu/(2 mu_s) - sum_{i>=2} P_i = [1 + sum_{m=1}^{nu-1} (1 - Q(m, x))] / (2 mu_s)``.

    The paper prints ``{nu - 1 - sum_{k=0}^{nu-2} Q(k+1, x)} / (2 mu_s)``,
    which is short by ``1/(2 mu_s)`` (it gives ``P_1(0) = 0``); see
    :func:`paper_p1`.  All sums are of positive Poisson terms computed in
    log space (:func:`_poisson_terms`); ``1 - Q`` is summed from the tail, so
    there is no cancellation and no overflow for large ``nu`` and ``x``.

    Parameters
    ----------
    alpha : float or array_like
        Tilt(s) in ``[0, pi/2]``.
    mu_s_mean, mu_d : float
        Mean static and dynamic friction coefficients, ``mu_s_mean > mu_d``.
    nu : None, "fixed", "alpha" or int
        Number of bins in the closed form.  ``None`` or ``"fixed"``: ``nu(0)``
        (the paper's solution, initial number of bins kept fixed; probability
        is conserved).  ``"alpha"``: ``nu(alpha)`` substituted in the
        fixed-``nu`` solution, as the paper does for ``P_3`` around
        Eq. (not_neg); this is not a solution of the ODEs across a change
        of ``nu`` and does not conserve probability (see
        :func:`integrate_master_equations` for a consistent treatment).
        An int: that number of bins.

    Returns
    -------
    numpy.ndarray
        For scalar ``alpha``: shape ``(nu,)``, index 0 is bin 1 (the peak).
        For an array: shape ``alpha.shape + (width,)`` with ``width`` the
        largest ``nu`` used; bins beyond a row's ``nu`` are zero.
    """
    dmu = _check_friction(mu_s_mean, mu_d)
    a = _check_alpha(alpha)
    flat = a.reshape(-1)
    nus = _resolve_nu(nu, flat, mu_s_mean, mu_d)
    width = int(nus.max())
    lower, tail = _poisson_sums(flat / (2.0 * dmu), width)
    rows = np.arange(flat.size)[:, None]
    m = nus[:, None] - np.arange(width)[None, :]            # Q index for bin c+1
    p = np.where(m >= 1, lower[rows, np.clip(m, 0, None)], 0.0)
    # column M of cum_tail: sum_{m=1}^{M} (1 - Q(m, x)), M = 0..width-1
    cum_tail = np.concatenate(
        [np.zeros((flat.size, 1)), np.cumsum(tail[:, 1:width], axis=1)], axis=1)
    p[:, 0] = 1.0 + cum_tail[rows[:, 0], nus - 1]
    p /= 2.0 * mu_s_mean
    return p[0] if a.ndim == 0 else p.reshape(a.shape + (width,))


def paper_p1(alpha: ArrayLike, mu_s_mean: float, mu_d: float, nu=None,
             as_printed: bool = False):
    """``P_1`` by the paper's double sum of Eq. (model), for comparison.

    ``P_1 = {c + nu - 1 - sum_{k=0}^{nu-2} [sum_{j=0}^{k} x^j/j!] e^{-x}} / (2 mu_s)``
    with ``c = 1`` (corrected: satisfies ``P_1(0) = 1/(2 mu_s)`` and the
    ODEs) or ``c = 0`` (``as_printed=True``: the formula as printed, which
    gives ``P_1(0) = 0``).  Evaluated literally, so it loses precision by
    cancellation for large ``nu``; :func:`bin_heights` does not.  ``nu`` as
    in :func:`bin_heights`.
    """
    dmu = _check_friction(mu_s_mean, mu_d)
    a = _check_alpha(alpha)
    flat = a.reshape(-1)
    nus = _resolve_nu(nu, flat, mu_s_mean, mu_d)
    lower, _ = _poisson_sums(flat / (2.0 * dmu), int(nus.max()))
    inner = np.cumsum(lower[:, 1:], axis=1)                 # sum_{k=0}^{K} Q(k+1)
    rows = np.arange(flat.size)
    s = np.where(nus >= 2, inner[rows, np.maximum(nus - 2, 0)], 0.0)
    p1 = ((0.0 if as_printed else 1.0) + nus - 1 - s) / (2.0 * mu_s_mean)
    return float(p1[0]) if a.ndim == 0 else p1.reshape(a.shape)


def crude_bin_heights(alpha: ArrayLike, mu_s_mean: float, mu_d: float):
    """Crude limit, Eq. (crude): ``P_1 ~ (1 + alpha/(2 dmu)) / (2 mu_s)``, ``P_i ~ 1/(2 mu_s)``.

    Valid for ``nu - i >> 1`` (far from the lower bound) and small ``alpha``.

    Returns
    -------
    (p1, p_other) : tuple
        ``P_1`` (same shape as ``alpha``) and the plateau value ``1/(2 mu_s)``.
    """
    dmu = _check_friction(mu_s_mean, mu_d)
    a = _check_alpha(alpha)
    return (1.0 + a / (2.0 * dmu)) / (2.0 * mu_s_mean), 1.0 / (2.0 * mu_s_mean)


def _master_rhs(p: np.ndarray, n: int, rate: float) -> np.ndarray:
    """Right-hand side of the master equations with ``n`` active bins."""
    d = np.zeros_like(p)
    if n >= 2:
        d[0] = p[1]
        d[1:n] = -p[1:n]
        d[1:n - 1] += p[2:n]
    return rate * d


def integrate_master_equations(alphas: ArrayLike, mu_s_mean: float, mu_d: float,
                               variable_nu: bool = False, method: str = "rk4",
                               steps_per_unit: int = 200) -> np.ndarray:
    """Integrate the master equations of Sec. IV-B numerically (fixed-step RK4).

    Starts from ``P_i(0) = 1/(2 mu_s)``, ``i = 1..nu(0)``, and advances the
    same ODEs as :func:`bin_heights` with classical RK4, vectorised over the
    bins.  The step is uniform inside each interval between output angles
    (and bin removals), with ``steps_per_unit`` steps per unit of the reduced
    angle ``x = alpha / (2 dmu)`` (the rates are ``1/(2 dmu)``, so the
    accuracy does not depend on ``dmu``); the default 200 gives errors
    below ``1e-12`` against the closed form.

    ``variable_nu=False``: ``nu = nu(0)`` throughout (the paper's setting; the
    result equals the closed form).

    ``variable_nu=True``: the number of active bins follows ``nu(alpha)`` of
    :func:`n_bins`.  Between bin edges the ODEs are those with the current
    ``nu`` (the lowest bin only empties into the bin above it).  When the
    lower bound ``sin(alpha) - mu_s_mean`` reaches the upper edge of the
    lowest bin (``sin(alpha) = 2 mu_s - 2 dmu (nu - 1)``, located with
    ``asin`` and the rounding of :func:`n_bins`, and stepped to), that bin
    is removed and **its remaining mass is added to the new lowest bin**
    (the forces it holds are all above the new lower bound, so they belong
    there): probability is conserved.  Removed bins are reported as zero.
    The model lets the lowest bin decay exponentially, whereas the lower
    bound sweeps through it at a constant rate, so some mass is always left
    at removal (``e^{-1}`` of bin 12 at the first edge for ``(0.6, 0.55)``).

    Parameters
    ----------
    alphas : array_like
        Output angles (1-d, any order), in ``[0, pi/2]``.
    mu_s_mean, mu_d : float
        Friction coefficients, ``mu_s_mean > mu_d``.
    variable_nu : bool
        See above.
    method : {"rk4"}
        Time stepper (only RK4 is provided).
    steps_per_unit : int
        RK4 steps per unit of ``alpha / (2 dmu)``.

    Returns
    -------
    numpy.ndarray
        Shape ``(len(alphas), nu(0))``; column 0 is bin 1.
    """
    dmu = _check_friction(mu_s_mean, mu_d)
    a = _check_alpha(alphas, "alphas")
    if a.ndim != 1:
        raise ValueError(f"alphas must be one-dimensional, got shape {a.shape}")
    if method != "rk4":
        raise ValueError(f"method must be 'rk4', got {method!r}")
    if not (isinstance(steps_per_unit, (int, np.integer)) and steps_per_unit >= 1):
        raise ValueError(f"steps_per_unit must be a positive int, got {steps_per_unit!r}")
    nu0 = n_bins(0.0, mu_s_mean, mu_d)
    rate = 1.0 / (2.0 * dmu)
    # events: (angle, kind, payload); kind 0 = bin removal (new nu), 1 = output.
    # At equal angles the removal comes first, since nu(edge) is the new value.
    events = [(float(v), 1, j) for j, v in enumerate(a)]
    if variable_nu and a.size:
        events += [(edge, 0, k) for edge, k in _bin_edges(mu_s_mean, mu_d)
                   if edge <= a.max()]
    events.sort()
    out = np.zeros((a.size, nu0))
    p = np.full(nu0, 1.0 / (2.0 * mu_s_mean))
    n, here = nu0, 0.0
    for angle, kind, payload in events:
        if angle > here:
            steps = max(1, math.ceil((angle - here) * rate * steps_per_unit))
            h = (angle - here) / steps
            for _ in range(steps):
                k1 = _master_rhs(p, n, rate)
                k2 = _master_rhs(p + 0.5 * h * k1, n, rate)
                k3 = _master_rhs(p + 0.5 * h * k2, n, rate)
                k4 = _master_rhs(p + h * k3, n, rate)
                p = p + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            here = angle
        if kind == 0:
            if payload < n:  # remove bins payload+1..n, masses into bin payload
                p[payload - 1] += p[payload:n].sum()
                p[payload:n] = 0.0
                n = payload
        else:
            out[payload] = p
    return out


def probability_total(p: ArrayLike, mu_s_mean: float, mu_d: float):
    """Total probability ``2 dmu sum_i P_i`` (sum over the last axis).

    The master equations conserve ``sum_i P_i``, so this stays at its initial
    value ``nu(0) dmu / mu_s_mean``; it equals 1 when ``mu_s_mean / dmu`` is
    an integer (e.g. ``(0.6, 0.55)``: 12 bins).  Otherwise the lowest bin
    reaches below ``-mu_s_mean`` and the total exceeds 1 (by less than
    ``2 dmu / (2 mu_s)``).
    """
    dmu = _check_friction(mu_s_mean, mu_d)
    return 2.0 * dmu * np.sum(np.asarray(p, dtype=float), axis=-1)


# --------------------------------------------------------------------------
# transition angle (Eqs. not_neg and cond)
# --------------------------------------------------------------------------
def transition_angle_stirling(mu_s_mean: float) -> float:
    """Stirling estimate of the transition angle, ``2 mu_s / (1 + e)`` (Eq. cond).

    0.32273 for ``mu_s_mean = 0.6`` (the paper quotes 0.32; simulations show
    the change near 0.38-0.4).
    """
    if not (np.isscalar(mu_s_mean) and math.isfinite(mu_s_mean) and mu_s_mean > 0):
        raise ValueError(f"mu_s_mean must be a positive finite number, got {mu_s_mean!r}")
    return 2.0 * mu_s_mean / (1.0 + math.e)


def _nu_segments(mu_s_mean: float, mu_d: float):
    """Intervals ``[lo, hi)`` of ``[0, pi/2]`` on which ``nu(alpha)`` is constant."""
    edges = [0.0] + [edge for edge, _ in _bin_edges(mu_s_mean, mu_d)] + [0.5 * math.pi]
    return [(lo, hi, n_bins(lo, mu_s_mean, mu_d)) for lo, hi in zip(edges[:-1], edges[1:])
            if hi > lo]


def transition_angle_exact(mu_s_mean: float, mu_d: float, level: float = 0.1) -> float:
    """Smallest alpha with ``x^m / m! >= level``, ``m = nu(alpha) - 2`` (Eq. not_neg).

    ``x = alpha / (2 dmu)`` and ``nu(alpha)`` from :func:`n_bins`; no Stirling
    approximation.  The left-hand side jumps where ``nu`` drops, so the
    angle range is split at the bin edges (exact, from ``asin``); on each
    piece ``m`` is constant and the left-hand side increases with alpha,
    so the condition either holds at the start of the piece (a jump) or is
    met at ``x* = exp((log(level) + lgamma(m + 1)) / m)`` (closed form, no
    bisection needed), or not in that piece.  For ``(0.6, 0.55)``, level 0.1:
    alpha = 0.2823 (``nu = 10``), below the Stirling value 0.3227; 0.3201,
    0.3232, 0.3245 for ``mu_d = 0.59, 0.595, 0.5995``.  As ``dmu -> 0`` the
    condition becomes ``e x = nu``, i.e. ``e alpha + sin(alpha) = 2 mu_s``
    (root 0.3242 for ``mu_s = 0.6``), which Eq. (cond) simplifies further
    with ``sin(alpha) ~ alpha``.

    Returns
    -------
    float
        The angle, or ``nan`` if the condition is never met below ``pi/2``.
    """
    dmu = _check_friction(mu_s_mean, mu_d)
    log_level = math.log(_check_level(level))
    for lo, hi, nu in _nu_segments(mu_s_mean, mu_d):
        m = nu - 2
        if m < 0:
            continue
        if m == 0:  # x^0/0! = 1 >= level
            return lo
        if lo > 0 and m * math.log(lo / (2 * dmu)) - math.lgamma(m + 1) >= log_level:
            return lo
        x_star = math.exp((log_level + math.lgamma(m + 1)) / m)
        if lo <= 2 * dmu * x_star < hi:
            return 2 * dmu * x_star
    return math.nan


def transition_angle_from_p3(mu_s_mean: float, mu_d: float, level: float = 0.1) -> float:
    """Smallest alpha with relative deficit ``1 - 2 mu_s P_3(alpha) >= level``.

    ``P_3`` is the closed form of Eq. (model) evaluated with ``nu(alpha)``,
    as in the paper's argument before Eq. (not_neg):
    ``1 - 2 mu_s P_3 = 1 - Q(m, x) = sum_{k>=m} x^k e^{-x} / k!``,
    ``m = nu(alpha) - 2``, the Poisson tail.  The paper replaces this tail by
    ``x^m / m!`` (its first term without the factor ``e^{-x}`` and without the
    higher terms), which overestimates it (by a factor ~``e^x (1 - x/(m+1))``, about 11
    at ``x = 2.8, m = 8``) and so gives an earlier angle.  Same piecewise search as
    :func:`transition_angle_exact`, with bisection (60 halvings) inside a
    piece of constant ``nu``, where the tail increases with alpha.  For
    ``(0.6, 0.55)``, level 0.1: alpha = 0.3895 (``nu = 9``), in the range
    0.38-0.4 seen in the simulations, but the result depends on the level
    (0.2906, 0.3047, 0.3285, 0.4115 for levels 0.01, 0.03, 0.05, 0.2) and
    on ``dmu``: as ``dmu -> 0`` the tail reaches O(1) where ``x ~ m``, i.e.
    ``alpha + sin(alpha) ~ 2 mu_s`` (about 0.61 for ``mu_s = 0.6``; 0.558
    for ``mu_d = 0.595``), whereas Eq. (not_neg) tends to the Stirling
    value.  With ``nu(alpha)`` in the fixed-``nu`` solution the mass of the
    removed bins is dropped; in the mass-conserving integration
    (:func:`integrate_master_equations` with ``variable_nu=True``) the
    deficit of ``P_3`` reaches 0.1 only near alpha = 0.73 for
    ``(0.6, 0.55)``, beyond the avalanche.

    Returns
    -------
    float
        The angle, or ``nan`` if the condition is never met below ``pi/2``.
    """
    dmu = _check_friction(mu_s_mean, mu_d)
    level = _check_level(level)

    def deficit(alpha: float, m: int) -> float:
        if m <= 0:
            return 1.0
        _, tail = _poisson_sums(np.array([alpha / (2.0 * dmu)]), m)
        return float(tail[0, m])

    for lo, hi, nu in _nu_segments(mu_s_mean, mu_d):
        m = nu - 2
        if m < 0:
            continue
        if deficit(lo, m) >= level:
            return lo
        if deficit(hi, m) < level:  # limit at the right end of the piece
            continue
        a, b = lo, hi
        for _ in range(60):
            c = 0.5 * (a + b)
            a, b = (a, c) if deficit(c, m) >= level else (c, b)
        return b
    return math.nan
