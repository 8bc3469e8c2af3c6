"""Static DC state estimation under bad-data detection (weighted least squares + residual tests).

The model is ``z = H θ + e``, ``e ~ N(0, R)``, with H of full column rank n and m > n meters.
Weighted least squares (WLS) with ``W = R⁻¹``:

    θ̂ = K z,   K = (H' W H)⁻¹ H' W,        r = z − H θ̂ = (I − H K) z

Two bad-data tests:

- **χ² residual test**: ``J = r' W r``; without bad data J is χ² with m − n degrees of freedom,
  so the alarm ``J > τ`` with ``τ = χ²_{m−n}`` upper-α quantile has false-alarm rate exactly α.
- **Largest normalised residual (LNR)**: ``r_i / sqrt(Ω_ii)``, ``Ω = cov(r) = R − H (H'WH)⁻¹ H'``;
  the alarm is ``max_i |r_i / sqrt(Ω_ii)| > λ``. The default λ is Šidák's: the two-sided normal
  quantile at ``1 − (1 − α)^{1/m}`` per meter, so the false-alarm rate is at most α (Šidák's
  inequality holds for any correlation of the normalised residuals). Meters with ``Ω_ii = 0``
  (critical meters: their residual is identically zero, bad data on them cannot be seen) are
  left out of the maximum.

Injection ``a`` (a false-data vector added to z). Whitening with ``R = L L'`` turns J into
``|(I − P) L⁻¹ (e + a)|²``, P the orthogonal projector on the columns of ``L⁻¹ H``, so under
attack J is *non-central* χ² with m − n degrees of freedom and non-centrality

    λ(a) = |(I − P) L⁻¹ a|² = a' W (I − H K) a

and the χ² test detects a with probability ``P[χ²_{m−n}(λ(a)) > τ]`` (exact). Every ``a = H c``
has λ = 0 and leaves the residual unchanged (the estimate moves by exactly c), so it is detected
with probability α, the false-alarm rate: undetectable (Liu, Ning & Reiter 2009). See
docs/guide/stealth.md.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import linalg, stats

from fdia_env._validation import (
    as_matrix,
    check_int,
    check_positions,
    check_psd,
    check_symmetric,
)
from fdia_env.stealth.tails import ncx2_sf

TESTS = ("chi2", "lnr")
"""Bad-data tests: the χ² residual test and the largest-normalised-residual test."""

_CRITICAL_RTOL = 1e-10


def check_alpha(alpha: Any) -> float:
    """Return ``alpha`` as a float in (0, 1) or raise ``ValueError`` naming it."""
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float, np.integer, np.floating)):
        raise ValueError(f"alpha must be a false-alarm rate in (0, 1), got {alpha!r}")
    alpha = float(alpha)
    if not (0.0 < alpha < 1.0):
        raise ValueError(f"alpha must be a false-alarm rate in (0, 1), got {alpha}")
    return alpha


def sidak_threshold(alpha: float, m: int) -> float:
    """LNR threshold with family-wise false-alarm rate at most ``alpha`` over ``m`` meters."""
    per_meter = -np.expm1(np.log1p(-alpha) / m)  # 1 − (1 − α)^{1/m}, accurate for small α
    return float(stats.norm.isf(per_meter / 2.0))


@dataclass(frozen=True, eq=False)
class StaticEstimation:
    """WLS state estimation with a χ² and an LNR bad-data test (see the module docstring).

    Build it with :func:`static_estimation` (grid presets, cases, your own H).

    Attributes:
        H: (m, n) measurement matrix, full column rank, m > n.
        R: (m, m) meter noise covariance (positive definite).
        alpha: False-alarm rate of the χ² test (and the bound for the default LNR threshold).
        lnr_threshold: λ of the LNR test.
        meters: (m,) meter names.
        grid: The :class:`~fdia_env.systems.grid.GridModel` the model was built from, or ``None``
            for a user's own H.

    Derived:
        K: (n, m) the WLS gain, ``θ̂ = K z``.
        S: (m, m) the residual operator ``I − H K``.
        Omega: (m, m) residual covariance without bad data, ``R − H (H'WH)⁻¹ H'``.
        dof: m − n.
        threshold: τ of the χ² test, the upper-α quantile of χ² with ``dof`` degrees of freedom.
        critical: (m,) bool, meters whose residual is identically zero (``Ω_ii = 0``).
    """

    H: np.ndarray
    R: np.ndarray
    alpha: float
    lnr_threshold: float
    meters: tuple[str, ...]
    grid: Any = None
    K: np.ndarray = field(init=False, repr=False)
    S: np.ndarray = field(init=False, repr=False)
    Omega: np.ndarray = field(init=False, repr=False)
    dof: int = field(init=False)
    threshold: float = field(init=False)
    critical: np.ndarray = field(init=False, repr=False)
    _Linv: np.ndarray = field(init=False, repr=False)
    _Q: np.ndarray = field(init=False, repr=False)
    _lnr_scale: np.ndarray = field(init=False, repr=False)
    _diag_Linv: np.ndarray | None = field(init=False, repr=False)

    def __post_init__(self) -> None:
        m, n = self.H.shape
        L = np.linalg.cholesky(self.R)
        Linv = linalg.solve_triangular(L, np.eye(m), lower=True)
        Hw = Linv @ self.H
        Q, Rq = np.linalg.qr(Hw)
        K = linalg.solve_triangular(Rq, Q.T @ Linv)  # (H'WH)⁻¹ H'W
        S = np.eye(m) - self.H @ K
        HG = self.H @ linalg.solve_triangular(
            Rq, linalg.solve_triangular(Rq.T, self.H.T, lower=True)
        )
        Omega = self.R - HG
        Omega = (Omega + Omega.T) / 2.0
        diag = np.diag(Omega)
        critical = diag <= _CRITICAL_RTOL * np.diag(self.R)
        values = {
            "K": K,
            "S": S,
            "Omega": Omega,
            "dof": m - n,
            "threshold": float(stats.chi2.isf(self.alpha, m - n)),
            "critical": critical,
            "_Linv": Linv,
            "_Q": Q,
        }
        for name, value in values.items():
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)
        is_diag = not np.any(self.R - np.diag(np.diag(self.R)))
        object.__setattr__(self, "_diag_Linv", np.diag(Linv).copy() if is_diag else None)
        scale = np.where(critical, 1.0, np.sqrt(np.where(critical, 1.0, diag)))
        object.__setattr__(self, "_lnr_scale", scale)

    @property
    def m(self) -> int:
        """Number of meters."""
        return self.H.shape[0]

    @property
    def n(self) -> int:
        """Number of states."""
        return self.H.shape[1]

    def meter_positions(self, meters: Any, param: str = "protected") -> np.ndarray:
        """Sorted unique positions of ``meters`` (positions 0..m−1 or names), ``None`` = none.

        Raises:
            ValueError: Naming ``param``, for an unknown name or position or another type.
        """
        if meters is None:
            return np.zeros(0, dtype=np.int64)
        where = {name: i for i, name in enumerate(self.meters)}
        return check_positions(param, meters, where, self.m, "meter")

    def _z(self, name: str, z: Any) -> np.ndarray:
        arr = np.asarray(z, dtype=np.float64)
        if arr.ndim == 0 or arr.shape[-1] != self.m:
            raise ValueError(f"{name} must have shape (..., {self.m}), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite (no NaN or inf)")
        return arr

    def estimate(self, z: Any) -> np.ndarray:
        """(..., n) WLS estimates θ̂ = K z of (..., m) measurements."""
        return self._z("z", z) @ self.K.T

    def residual(self, z: Any) -> np.ndarray:
        """(..., m) residuals r = z − H θ̂."""
        return self._z("z", z) @ self.S.T

    def _whiten(self, x: np.ndarray) -> np.ndarray:
        """``L⁻¹ x`` along the last axis (elementwise when R is diagonal)."""
        if self._diag_Linv is not None:
            return x * self._diag_Linv
        return x @ self._Linv.T

    def _parts(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(|(I − P) L⁻¹ x|², |L⁻¹ x|)`` along the last axis."""
        w = self._whiten(x)
        r = w - (w @ self._Q) @ self._Q.T
        return np.einsum("...i,...i->...", r, r), np.linalg.norm(w, axis=-1)

    def statistic(self, z: Any) -> np.ndarray:
        """(...,) the χ² statistic J = r' W r."""
        return self._parts(self._z("z", z))[0]

    def normalized_residuals(self, z: Any) -> np.ndarray:
        """(..., m) ``r_i / sqrt(Ω_ii)`` (0 on critical meters)."""
        r = self.residual(z)
        return np.where(self.critical, 0.0, r / self._lnr_scale)

    def alarm(self, z: Any, test: str = "chi2") -> np.ndarray:
        """(...,) bool: the bad-data test ``test`` (``"chi2"`` or ``"lnr"``) raises an alarm."""
        test = _check_test(test)
        if test == "chi2":
            return self.statistic(z) > self.threshold
        return np.max(np.abs(self.normalized_residuals(z)), axis=-1) > self.lnr_threshold

    def injection(self, a: Any) -> np.ndarray:
        """``a`` as a finite (..., m) float array (``ValueError`` naming ``a`` otherwise)."""
        return self._z("a", a)

    def estimate_shift(self, a: Any) -> np.ndarray:
        """(..., n) the change ``K a`` an injection makes to the estimate (``c`` for a = H c)."""
        return self.injection(a) @ self.K.T

    def noncentrality(self, a: Any) -> np.ndarray:
        """(...,) the non-centrality ``λ(a) = |(I − P) L⁻¹ a|²`` of J under injection ``a``.

        0 where :meth:`is_stealthy`: the computed residual of ``a = H c`` is rounding of size
        ``|a| · 1e-16``, not part of λ.
        """
        lam, size = self._parts(self.injection(a))
        return np.where(rounding_residual(lam, size), 0.0, lam)

    def attacked_residual(self, e: Any, a: Any) -> np.ndarray:
        """(..., m) the residual of readings ``e + a`` (noise ``e``, injection ``a``).

        ``r(e) + r(a)`` (the residual is linear), with ``r(a)`` zero where :meth:`is_stealthy`:
        the residual of the sum would carry ``a``'s rounding, ``|a| · 1e-16``, which alone
        raises the alarm on an undetectable ``a = H c`` from ``|a| ≈ 1e12`` of the noise's
        scale on. Its :meth:`statistic` and :meth:`alarm` are those of ``e + a``.
        """
        e, a = self._z("e", e), self.injection(a)
        lam, size = self._parts(a)
        seen = ~rounding_residual(lam, size)
        return e @ self.S.T + (a @ self.S.T) * seen[..., None]

    def detection_probability(self, a: Any) -> np.ndarray:
        """(...,) exact probability that the χ² test alarms under injection ``a``.

        ``P[χ²_{m−n}(λ(a)) > τ]``; exactly ``alpha`` where :meth:`is_stealthy` (``a = H c``).
        """
        lam, size = self._parts(self.injection(a))
        stealthy = rounding_residual(lam, size)
        out = np.full(lam.shape, self.alpha)
        seen = ~stealthy
        if np.any(seen):  # 1.0 exactly far in the tail (fdia_env.stealth.tails)
            out[seen] = ncx2_sf(self.threshold, self.dof, lam[seen])
        return out if out.ndim else float(out)

    def detection_rate(
        self, a: Any, samples: int = 10_000, seed: int | None = None, test: str = "chi2"
    ) -> float:
        """Monte-Carlo detection rate of the injection ``a`` (m,) over ``samples`` noise draws.

        The χ² rate estimates :meth:`detection_probability`; the LNR test has no closed form,
        so this is how its detection probability is measured.
        """
        a = self.injection(a)
        if a.ndim != 1:
            raise ValueError(f"a must be one (m,) injection, got shape {a.shape}")
        samples = check_int("samples", samples, minimum=1)
        test = _check_test(test)
        rng = np.random.default_rng(seed)
        L = np.linalg.cholesky(self.R)
        e = rng.standard_normal((samples, self.m)) @ L.T
        return float(np.mean(self.alarm(self.attacked_residual(e, a), test)))

    def is_stealthy(self, a: Any, tol: float = 1e-9) -> np.ndarray:
        """(...,) bool: ``a`` lies in the column space of H (its residual is zero to ``tol``).

        ``tol`` is relative to ``|L⁻¹ a|``: the injection's whitened size.
        """
        lam, size = self._parts(self.injection(a))
        return rounding_residual(lam, size, tol)


def rounding_residual(lam: Any, size: Any, tol: float = 1e-9) -> Any:
    """Where a residual of squared size ``lam`` is rounding of a whitened injection of ``size``.

    ``sqrt(lam) <= tol · max(size, 1e-300)``, on numpy arrays or torch tensors.
    """
    return lam**0.5 <= tol * size.clip(min=1e-300)


def _check_test(test: Any) -> str:
    if test not in TESTS:
        raise ValueError(f"test must be one of {list(TESTS)}, got {test!r}")
    return test


def _check_H(H: Any) -> np.ndarray:
    H = as_matrix("H", H)
    m, n = H.shape
    if m <= n:
        raise ValueError(
            f"H must have more meters (rows) than states (columns) for bad-data detection, got "
            f"shape {H.shape}"
        )
    rank = np.linalg.matrix_rank(H)
    if rank < n:
        raise ValueError(
            f"H must have full column rank (the states must be observable), got rank {rank} < "
            f"{n} columns"
        )
    return H


def _check_R(R: Any, sigma: Any, m: int, default: np.ndarray | None) -> np.ndarray:
    if R is not None and sigma is not None:
        raise ValueError("give R or sigma, not both")
    if R is not None:
        R = as_matrix("R", R, shape=(m, m))
        check_symmetric("R", R)
        check_psd("R", R, strict=True)
        return R
    if sigma is None:
        if default is None:
            return np.eye(m)
        sigma = default
    try:
        s = np.array(sigma, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"sigma must be a number or {m} meter standard deviations") from exc
    if s.size == 1:
        s = np.full(m, s[0])
    if s.size != m or not np.all(np.isfinite(s)) or np.any(s <= 0.0):
        raise ValueError(
            f"sigma must be one positive number or {m} positive finite meter standard "
            f"deviations, got {np.asarray(sigma).tolist()}"
        )
    return np.diag(s**2)


def grid_source(source: Any) -> Any:
    """The :class:`GridModel` of a case name, a grid preset name or a GridModel, else ``None``."""
    from fdia_env.systems.grid import CASES, GridModel

    if isinstance(source, GridModel):
        return source
    if isinstance(source, str):
        case = source.removeprefix("grid-")
        if case not in CASES:
            raise ValueError(
                f"source must be a grid case {sorted(CASES)}, a grid preset "
                f"{['grid-' + c for c in sorted(CASES)]}, a GridModel or an (m, n) matrix H, "
                f"got {source!r}"
            )
        return _grid_case(case)
    return None


@functools.cache
def _grid_case(case: str) -> Any:
    """The default grid model of a case, built once (it is immutable: read-only arrays)."""
    from fdia_env.systems.grid import grid_model

    return grid_model(case)


def static_estimation(
    source: Any = "ieee14",
    *,
    alpha: float = 0.05,
    R: Any = None,
    sigma: Any = None,
    lnr_threshold: float | None = None,
    meters: Sequence[str] | None = None,
) -> StaticEstimation:
    """Static WLS state estimation with bad-data detection.

    Args:
        source: A grid case (``"ieee14"``, ``"ieee30"``, ``"ieee57"``, ``"ieee118"``,
            ``"ieee300"``), a grid preset name (``"grid-ieee14"``, ...), a
            :class:`~fdia_env.systems.grid.GridModel` (e.g. ``grid_model(case, flows=...)``) or
            your own (m, n) matrix H (full column rank, m > n). For a grid the state is the
            angles of every bus but the slack and the meters are the grid model's (an injection
            at every bus and a flow at the from end of every branch by default).
        alpha: False-alarm rate of the χ² test, in (0, 1).
        R: (m, m) positive definite noise covariance, or ``None``.
        sigma: Meter standard deviations instead of R (one number or m of them). Default: the
            grid's σ_flow / σ_injection, or 1 for your own H.
        lnr_threshold: λ of the LNR test (> 0); default Šidák's threshold at ``alpha``.
        meters: Meter names (default the grid's sensor names, or ``z0``, ``z1``, ...).

    Returns:
        The :class:`StaticEstimation`.

    Raises:
        ValueError: Naming the parameter: an unknown case, an H without full column rank or
            with m ≤ n, alpha outside (0, 1), R not positive definite, a bad sigma or threshold.

    Example:
        >>> est = static_estimation("ieee14")
        >>> est.m, est.n, est.dof, round(est.threshold, 3)
        (34, 13, 21, 32.671)
    """
    alpha = check_alpha(alpha)
    grid = grid_source(source)
    default_sigma = None
    if grid is not None:
        keep = np.arange(grid.network.n_buses) != grid.network.slack
        H = _check_H(grid.H_full[:, keep])
        from fdia_env.systems.grid.measurements import (
            DEFAULT_SIGMA_FLOW,
            DEFAULT_SIGMA_INJECTION,
            _label,
        )

        default_sigma = np.array(
            [
                DEFAULT_SIGMA_INJECTION if mt.kind == "injection" else DEFAULT_SIGMA_FLOW
                for mt in grid.meters
            ]
        )
        names = tuple(_label(grid.network, mt) for mt in grid.meters)
    else:
        H = _check_H(source)
        names = tuple(f"z{i}" for i in range(H.shape[0]))
    m = H.shape[0]
    R = _check_R(R, sigma, m, default_sigma)
    if meters is not None:
        names = tuple(str(s) for s in meters)
        if len(names) != m:
            raise ValueError(f"meters must name all {m} meters, got {len(names)} names")
    if lnr_threshold is None:
        lnr = sidak_threshold(alpha, m)
    else:
        if isinstance(lnr_threshold, bool) or not isinstance(
            lnr_threshold, (int, float, np.integer, np.floating)
        ):
            raise ValueError(f"lnr_threshold must be a number > 0, got {lnr_threshold!r}")
        lnr = float(lnr_threshold)
        if not (np.isfinite(lnr) and lnr > 0.0):
            raise ValueError(f"lnr_threshold must be a finite number > 0, got {lnr}")
    H = H.copy()
    H.setflags(write=False)
    R = np.array(R, dtype=np.float64)
    R.setflags(write=False)
    return StaticEstimation(H=H, R=R, alpha=alpha, lnr_threshold=lnr, meters=names, grid=grid)
