"""Random numbers keyed by (seed, slider, stop count), not by a shared stream.

docs/model.md, "Keyed randomness": the order in which sliders stop inside an event depends on
the time step, the backend and rounding.  If every draw came from one shared
stream, two runs of the same scene would diverge after a few events.  Here the
static coefficient that slider ``n`` draws at its ``k``-th stop is a pure
function of ``(seed, n, k)``: a counter-based generator built from a 32-bit
integer hash (Wellons' "lowbias32").  The Fortran kernel
(``fortran/sliders_random.f90``) implements the same function bit for bit; the
test suite checks that.

Conventions shared with the Fortran kernel:

* all keys are unsigned 32-bit integers; ``slider`` is 0-based;
* stop count ``k = 0`` is the coefficient drawn at preparation, the ``k``-th
  stop of a slider draws with ``k``;
* the preparation forces use the reserved count ``PREPARATION_STREAM``.
"""

from __future__ import annotations

import numpy as np

MASK32 = 0xFFFFFFFF
PREPARATION_STREAM = 0xFFFFFFFF
MAX_ATTEMPTS = 1000  # rejection attempts for mu_s > mu_d before giving up
# The transcendentals of the Box-Muller draw.  NumPy's own; a caller may put
# the C library's here (tests/test_backends.py does, for bit-for-bit checks
# against the Fortran kernel, which calls glibc).
TRANSCENDENTALS = {"log": np.log, "cos": np.cos}

_TWO_POW_26 = 67108864.0
_TWO_POW_53 = 9007199254740992.0


def mix32(x):
    """Wellons' lowbias32 integer hash on uint32 values (scalar or array)."""
    x = np.asarray(x, dtype=np.uint32)
    with np.errstate(over="ignore"):
        x = x ^ (x >> np.uint32(16))
        x = x * np.uint32(0x7FEB352D)
        x = x ^ (x >> np.uint32(15))
        x = x * np.uint32(0x846CA68B)
        x = x ^ (x >> np.uint32(16))
    return x


def key_hash(seed, slider, count, draw):
    """Hash of the key (seed, slider, count, draw); all uint32."""
    h = mix32(np.uint32(seed) ^ np.uint32(0x9E3779B9))
    h = mix32(h ^ np.asarray(slider, dtype=np.uint32))
    h = mix32(h ^ np.asarray(count, dtype=np.uint32))
    h = mix32(h ^ np.asarray(draw, dtype=np.uint32))
    return h


def uniform(seed, slider, count, draw):
    """Uniform double in the open interval (0, 1), 53 bits, keyed."""
    a = key_hash(seed, slider, count, 2 * np.asarray(draw, dtype=np.uint32)) >> np.uint32(5)
    b = key_hash(seed, slider, count, 2 * np.asarray(draw, dtype=np.uint32) + np.uint32(1)) >> np.uint32(6)
    return (a.astype(np.float64) * _TWO_POW_26 + b.astype(np.float64) + 0.5) / _TWO_POW_53


def static_coefficient(seed, slider, count, mu_s_mean, sigma_mu, mu_d):
    """The static coefficient slider ``slider`` draws at its ``count``-th stop.

    Gaussian of mean ``mu_s_mean`` and width ``sigma_mu`` (Box-Muller on two
    keyed uniforms), redrawn until it exceeds ``mu_d`` (paper Sec. II-C).
    Works on arrays of sliders/counts; returns float64 of the same shape.
    """
    slider = np.asarray(slider, dtype=np.uint32)
    count = np.broadcast_to(np.asarray(count, dtype=np.uint32), slider.shape)
    out = np.full(slider.shape, np.nan)
    pending = np.ones(slider.shape, dtype=bool)
    for attempt in range(MAX_ATTEMPTS):
        s, c = slider[pending], count[pending]
        u1 = uniform(seed, s, c, 2 * attempt)
        u2 = uniform(seed, s, c, 2 * attempt + 1)
        z = (np.sqrt(-2.0 * TRANSCENDENTALS["log"](u1))
             * TRANSCENDENTALS["cos"](2.0 * np.pi * u2))
        mu = mu_s_mean + sigma_mu * z
        ok = mu > mu_d
        idx = np.flatnonzero(pending)
        out[idx[ok]] = mu[ok]
        pending[idx[ok]] = False
        if not pending.any():
            return out
    raise RuntimeError(
        f"static coefficient: no draw above mu_d={mu_d} in {MAX_ATTEMPTS} attempts "
        f"(mu_s_mean={mu_s_mean}, sigma_mu={sigma_mu})"
    )


def realisation_seed(base_seed: int, realisation: int) -> int:
    """Seed of realisation ``r`` of an ensemble: independent of rank count."""
    return int(key_hash(base_seed, realisation, 0xFFFFFFFE, 0))
