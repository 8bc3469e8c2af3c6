"""Tail probabilities of Gaussian quadratic forms (generalized chi-square), both tails accurate.

Every detector of this package decides D1 when a quadratic form ``q = y' A y`` of the innovation
``y = z − z̄ ~ N(0, Pzz_h)`` exceeds a threshold. With ``L L' = Pzz_h`` and ``y = L u``,
``q = u' (L' A L) u = Σ_i λ_i χ²_{k_i}`` (λ_i the eigenvalues of ``L' A L``, independent
chi-squares; ``k_i = 1`` here, 3 for the truncated second moments of
:mod:`fdia_env.detection.expected`), a central generalized chi-square. For A ⪰ 0 all λ_i >= 0.

The detection game multiplies these probabilities by second moments that grow like the attack
power a², so *both* tails must be accurate relative to their own size, not only to 1e-14 in
absolute terms: ``P(D0 | H1)`` of a strong attack is ~ a⁻³ and multiplies an error of size a².
:func:`gchisq_tails` returns the pair ``(P(q <= x), P(q > x))``, each computed directly:

- non-positive weights are exact zeros of the sum and are dropped; none left: ``q ≡ 0``;
- one distinct weight λ (total degrees of freedom k): exact, ``q / λ ~ χ²_k``
  (``scipy.stats.chi2.cdf`` / ``.sf``, each accurate in its own tail);
- otherwise the Laplace inversion integral through the *saddle point* ``c`` of
  ``K(t) − t x`` (``K(t) = −½ Σ k_i log(1 − 2 λ_i t)``, the cumulant generating function), for
  the tail on x's side of the mean (the other is one minus it):

      P(q <= x) = (1 / 2πi) ∫ e^{K(t) − t x} (−1/t) dt   on a path crossing the real axis at c < 0,
      P(q >  x) = (1 / 2πi) ∫ e^{K(t) − t x} (1/t) dt    at 0 < c < 1/(2 λ_max).

  The factor ``e^{K(c) − c x}`` (the Chernoff bound, in logarithms) carries the size of the
  tail, however small; the rest is an integral of order one without cancellation (the phase is
  stationary at c). The path ``t = c + (η²/4 + iη)/x`` (valid: the singularities 0 and
  ``1/(2λ_i)`` lie on the real axis to the right of c) makes ``|e^{−t x}| = e^{−c x − η²/4}`` a
  Gaussian in η, so one adaptive Gauss–Kronrod integral over ``η ∈ [0, 13.6]`` suffices (no slow
  oscillation to extrapolate). Near the mean, ``|c|`` is kept >= ``min(1/sd, 1/(4 λ_max))`` away
  from the pole at 0 (any c on the right side is exact; there the bound is <= e^{1/2}). Weights
  are scaled by the largest, so nothing overflows. Against a 40-digit reference (a positive
  one-dimensional convolution, ``mpmath``) the relative error of *both* tails is below 1e-13 for
  weight ratios up to 1e300 and tails down to 1e-150.

Imhof's formula (J. P. Imhof, Biometrika 48, 1961), :func:`imhof_sf`, is kept as an independent
cross-check; its absolute accuracy (~1e-14 in the central region) is no use for a tail of 1e-20.

Every quadrature reports its error estimate; when it exceeds the tolerance a
:class:`NumericalAccuracyWarning` names the integral and the estimate (never a silent wrong
number).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import scipy.integrate
import scipy.optimize
import scipy.stats

from fdia_env._validation import as_float_array, as_matrix, check_psd, check_square
from fdia_env.kalman import psd_sqrt

_DROP = 1e-12  # Imhof only: weights below this fraction of the largest are treated as zero
_EQUAL = 1e-12  # relative spread below which the weights count as equal (exact χ²_k)
_TOL = 1e-9  # relative error estimate above which a quadrature warns


class NumericalAccuracyWarning(RuntimeWarning):
    """A numerical integral or iteration missed its tolerance (the message says by how much)."""


def quadratic_form_weights(A: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Eigenvalues of ``L' A L`` (``L L' = cov``): ``y' A y = Σ λ_i χ²_1`` for ``y ~ N(0, cov)``.

    Raises:
        ValueError: Naming ``A`` or ``cov``: not a finite numeric matrix, ``A`` not square,
            ``cov`` not of ``A``'s shape or not symmetric PSD.
    """
    A = as_matrix("A", A)
    check_square("A", A)
    cov = as_matrix("cov", cov, shape=A.shape)
    check_psd("cov", cov)
    L = psd_sqrt(cov)
    M = L.T @ A @ L
    return np.linalg.eigvalsh(0.5 * (M + M.T))


def _quad(f, a, b, **kw) -> tuple[float, float]:
    """``scipy.integrate.quad`` as ``(value, error estimate)``; the caller checks the estimate."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", scipy.integrate.IntegrationWarning)
        out = scipy.integrate.quad(f, a, b, full_output=1, **kw)
    return float(out[0]), float(out[1])


def _warn_if_inaccurate(what: str, value: float, error: float, scale: float) -> None:
    if not np.isfinite(value) or error > _TOL * scale:
        warnings.warn(
            f"{what}: the quadrature's error estimate {error:.3g} exceeds the tolerance "
            f"{_TOL:g} x {scale:.3g} (value {value:.6g})",
            NumericalAccuracyWarning,
            stacklevel=3,
        )


def imhof_sf(x: float, weights: np.ndarray) -> float:
    """``P(Σ λ_i χ²_1 > x)``, ``x > 0``, by Imhof's formula (absolute accuracy ~1e-14)."""
    lam = np.asarray(weights, dtype=np.float64).reshape(-1)
    dof = np.ones_like(lam)
    keep = lam > _DROP * lam.max()
    lam, half_k = lam[keep], 0.5 * dof[keep]
    w = 0.5 * x

    def beta(u: float) -> float:
        return float(np.sum(half_k * np.arctan(lam * u)))

    def inv_u_rho(u: float) -> float:  # 1 / (u ρ(u)), ρ through logs to avoid overflow
        return float(np.exp(-0.5 * np.sum(half_k * np.log1p((lam * u) ** 2)))) / u

    u0 = 1.0 / w
    head, e1 = _quad(
        lambda u: np.sin(beta(u) - w * u) * inv_u_rho(u), 0.0, u0, limit=500,
        epsabs=1e-14, epsrel=1e-12,
    )  # fmt: skip
    cos_part, e2 = _quad(
        lambda u: np.sin(beta(u)) * inv_u_rho(u), u0, np.inf, weight="cos", wvar=w,
        limlst=500, limit=500, epsabs=1e-14,
    )  # fmt: skip
    sin_part, e3 = _quad(
        lambda u: np.cos(beta(u)) * inv_u_rho(u), u0, np.inf, weight="sin", wvar=w,
        limlst=500, limit=500, epsabs=1e-14,
    )  # fmt: skip
    value = 0.5 + (head + cos_part - sin_part) / np.pi
    _warn_if_inaccurate("Imhof integral", value, (e1 + e2 + e3) / np.pi, 1e-3)
    return value


def _log1p_pos(log_x: np.ndarray) -> np.ndarray:
    """``log(1 + e^{log_x})`` without overflow."""
    return np.logaddexp(0.0, log_x)


class _Saddle:
    """The saddle point ``c`` of ``K(t) − t x`` for one tail, in overflow-free form.

    Lower tail (``x`` below the mean): ``c = −g``, ``g > 0``, ``1 − 2 λ_i c = 1 + 2 λ_i g``.
    Upper tail: ``c = (1 − δ) / (2 λ_max)``, ``0 < δ < 1``,
    ``1 − 2 λ_i c = (1 − ρ_i) + ρ_i δ`` with ``ρ_i = λ_i / λ_max``.
    """

    def __init__(self, x: float, lam: np.ndarray, dof: np.ndarray, lower: bool) -> None:
        self.x, self.lam, self.dof, self.lower = x, lam, dof, lower
        self.top = float(lam.max())  # 1 after gchisq_tails' scaling
        self.log_lam = np.log(lam)
        mean = float(dof @ lam)
        if lower:  # K'(−g) = Σ k λ / (1 + 2 λ g) decreases from the mean to 0
            lo = math.log(mean - x) - math.log(2.0 * self.top) - math.log(mean)
            hi = math.log(dof.sum() / x)  # K(−g) < Σ k / (2 g) = x / 2 there
        else:  # K' increases from the mean (δ = 1) to ∞ (δ → 0)
            lo = math.log(0.5 * min(1.0, float(dof[np.argmax(lam)]) * self.top / x))
            hi = 0.0
        f = lambda s: self._slope(s) - x  # noqa: E731
        if lower:
            self.s = lo if f(lo) <= 0.0 else scipy.optimize.brentq(f, lo, hi, xtol=1e-14)
        else:
            self.s = hi if f(hi) >= 0.0 else scipy.optimize.brentq(f, lo, hi, xtol=1e-14)
        # near the mean the saddle approaches the pole of 1/t at 0: keep |c| >= min(1/sd, ...)
        # (any c on the right side is exact; there e^{K(c) − c x} <= e^{1/2}, no cancellation)
        c_min = 1.0 / math.sqrt(2.0 * float(dof @ lam**2))
        if lower:
            self.s = max(self.s, math.log(c_min))
        else:
            c_min = min(c_min, 0.25 / self.top)
            c = (1.0 - math.exp(self.s)) / (2.0 * self.top)
            if c < c_min:
                self.s = math.log(1.0 - 2.0 * self.top * c_min)

    def _terms(self, s: float) -> tuple[float, np.ndarray, np.ndarray]:
        """``(c, log(1 − 2 λ c), r = 2 λ / (1 − 2 λ c))`` at the parameter ``s``."""
        if self.lower:
            g = math.exp(s)
            log_d = _log1p_pos(math.log(2.0 * g) + self.log_lam)
            r = 2.0 * self.lam / (1.0 + 2.0 * self.lam * g)
            return -g, log_d, r
        delta = math.exp(s)
        rho = self.lam / self.top
        d = (1.0 - rho) + rho * delta
        return (1.0 - delta) / (2.0 * self.top), np.log(d), 2.0 * self.lam / d

    def _slope(self, s: float) -> float:
        return float(0.5 * self.dof @ self._terms(s)[2])  # K'(c) = Σ k λ / (1 − 2 λ c)

    def tail(self) -> float:
        """The tail probability by the contour integral through the saddle point."""
        c, log_d, r = self._terms(self.s)
        x, half_k = self.x, 0.5 * self.dof
        log_scale = float(-half_k @ log_d) - c * x  # K(c) − c x <= 0
        if log_scale < -745.0:  # below the smallest double: the tail is 0 to machine precision
            return 0.0
        sign = -1.0 if self.lower else 1.0
        # the path t = c + (η²/4 + i η) / x: |e^{−t x}| = e^{−c x − η²/4} decays like a Gaussian
        # in η instead of oscillating; dt = (η/2 + i) dη / x
        cx, r_x = c * x, (r / x).astype(complex)

        def integrand(eta: float) -> float:
            shift = complex(0.25 * eta * eta, eta)  # (t − c) x
            log_m = -(half_k @ np.log(1.0 - r_x * shift))  # K(t) − K(c)
            value = np.exp(log_m - shift) * complex(1.0, -0.5 * eta) / (cx + shift)
            return sign * value.real

        eta_max = math.sqrt(4.0 * 46.0)  # e^{−46} ~ 1e-20 of the value at η = 0
        head, err = _quad(integrand, 0.0, eta_max, limit=500, epsabs=0.0, epsrel=1e-12)
        integral = head / math.pi
        _warn_if_inaccurate("saddle-point tail integral", integral, err / math.pi, abs(integral))
        return float(math.exp(log_scale) * max(integral, 0.0))


def gchisq_tails(
    x: float, weights: np.ndarray, dof: np.ndarray | None = None
) -> tuple[float, float]:
    """``(P(q <= x), P(q > x))`` for ``q = Σ_i λ_i χ²_{k_i}``, each accurate relative to its size.

    Args:
        x: Threshold; ±inf allowed.
        weights: (m,) weights ``λ_i >= 0`` (rounding-level negatives are taken as 0).
        dof: (m,) degrees of freedom ``k_i > 0`` (default all 1).

    Returns:
        The lower and upper tail probabilities (they sum to 1 up to rounding).

    Raises:
        ValueError: If a weight is negative beyond rounding or not finite, a degree of freedom
            is not positive, or x is NaN.

    Example:
        >>> lo, up = gchisq_tails(5.0, [1e12, 1.0])  # a weight 1e12 times the threshold
        >>> f"{lo:.6e}", round(up, 12)
        ('1.565570e-06', 0.99999843443)
    """
    lam = _as_floats("weights", weights)
    k = np.ones_like(lam) if dof is None else _as_floats("dof", dof)
    if k.shape != lam.shape or not np.all(np.isfinite(k)) or np.any(k <= 0):
        raise ValueError(f"dof must be {lam.size} finite numbers > 0, got {k.tolist()}")
    if not np.all(np.isfinite(lam)):
        raise ValueError(f"weights must be finite, got {lam.tolist()}")
    top = float(lam.max()) if lam.size else 0.0
    if lam.size and lam.min() < -1e-9 * max(top, 1.0):
        raise ValueError(f"weights must be >= 0, got {lam.tolist()}")
    x = float(_as_floats("x", x, scalar=True)[0])
    if math.isnan(x):
        raise ValueError("x must not be NaN")
    keep = lam > 0.0
    lam, k = lam[keep], k[keep]
    if lam.size == 0:  # q ≡ 0
        return (0.0, 1.0) if x < 0 else (1.0, 0.0)
    if x <= 0.0:
        return 0.0, 1.0
    if math.isinf(x):
        return 1.0, 0.0
    if lam.max() - lam.min() <= _EQUAL * lam.max():
        total, scale = float(k.sum()), float(lam.mean())
        return float(scipy.stats.chi2.cdf(x / scale, total)), float(
            scipy.stats.chi2.sf(x / scale, total)
        )
    top = float(lam.max())  # the distribution scales: work with weights <= 1 (no overflow)
    lam, x = lam / top, x / top
    lam, k = lam[lam > 0.0], k[lam > 0.0]  # a weight below 1e-308 λ_max is 0 to every digit
    if x == 0.0:  # underflow: P(q <= x) ~ (x / λ_max)^{k/2} is below the smallest double
        return 0.0, 1.0
    saddle = _Saddle(x, lam, k, lower=x < float(k @ lam))
    small = min(1.0, saddle.tail())  # the tail on x's side of the mean, computed directly
    return (small, 1.0 - small) if saddle.lower else (1.0 - small, small)


def gchisq_sf(x: float | np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``P(Σ_i λ_i χ²_1 > x)`` for weights ``λ_i >= 0`` (central generalized chi-square).

    Args:
        x: Threshold(s), any shape; ±inf allowed.
        weights: (k,) non-negative weights.

    Returns:
        Tail probabilities, the shape of ``x`` (a 0-d array for a scalar); relative accuracy in
        the far tail as well (:func:`gchisq_tails`).

    Raises:
        ValueError: If a weight is negative (beyond rounding) or not finite, or x holds NaN.

    Example:
        >>> float(gchisq_sf(2.0, [1.0, 1.0]).round(12))  # χ²_2: exp(−x/2)
        0.367879441171
        >>> float(gchisq_sf(5.0, [3.0, 0.5]).round(7))
        0.2258398
    """
    return _map(x, weights, 1)


def gchisq_cdf(x: float | np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``P(Σ_i λ_i χ²_1 <= x)``, accurate relative to its size in the lower tail too."""
    return _map(x, weights, 0)


def _as_floats(name: str, value: object, scalar: bool = False) -> np.ndarray:
    """``value`` as a flat float64 array (one entry if ``scalar``), else ``ValueError``."""
    kind = "a real number" if scalar else "a real number or an array of real numbers"
    arr = as_float_array(name, value, kind).reshape(-1)
    if scalar and arr.size != 1:
        raise ValueError(f"{name} must be a single real number, got {value!r}")
    return arr


def _map(x: float | np.ndarray, weights: np.ndarray, which: int) -> np.ndarray:
    _as_floats("x", x)
    xs = np.asarray(x, dtype=np.float64)
    if np.any(np.isnan(xs)):
        raise ValueError(f"x must not be NaN, got {xs.tolist()}")
    out = np.empty(xs.shape)
    for idx, xv in np.ndenumerate(xs):
        out[idx] = gchisq_tails(float(xv), weights)[which]
    return out


def quadratic_tails(threshold: float, A: np.ndarray, cov: np.ndarray) -> tuple[float, float]:
    """``(P(y' A y <= threshold), P(y' A y > threshold))`` for ``y ~ N(0, cov)``, PSD ``A``.

    ``A`` is PSD by construction (e.g. ``Pzz0⁻¹ − Pzz1⁻¹``), so negative weights are rounding
    (of a difference of inverses, amplified by ``cov`` ~ a²) and are set to 0.
    """
    weights = np.clip(quadratic_form_weights(A, cov), 0.0, None)
    return gchisq_tails(float(threshold), weights)


def gchisq_sf_mc(
    x: float | np.ndarray, weights: np.ndarray, draws: int = 1_000_000, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Monte-Carlo cross-check of :func:`gchisq_sf`: ``(estimate, standard error)``."""
    lam = np.asarray(weights, dtype=np.float64).reshape(-1)
    rng = np.random.default_rng(seed)
    q = (rng.standard_normal((draws, lam.size)) ** 2) @ lam
    xs = np.asarray(x, dtype=np.float64)
    p = (q[:, None] > xs.reshape(1, -1)).mean(axis=0).reshape(xs.shape)
    return p, np.sqrt(p * (1.0 - p) / draws)
