"""The model of ``stealth_dynamic_v0``: a Kalman filter with a windowed χ² innovation detector.

System ``x[k+1] = F x[k] + w``, ``y[k] = H x[k] + v`` (``w ~ N(0, Q)``, ``v ~ N(0, R)``, the
stacked rows of the scenario's sensors), the steady-state Kalman filter
``x̂[k+1] = F x̂[k] + K z[k+1]`` on the innovation ``z[k+1] = y[k+1] − H F x̂[k]`` (covariance
``Σ = H P H' + R``, P the predicted steady state), and the windowed χ² detector of Mo &
Sinopoli (2010), ``g[k] = Σ_{j=k−w+1..k} z̃[j]' Σ⁻¹ z̃[j]`` over the last w
innovations the estimator receives, alarm when ``g[k] > τ``, τ the upper-α quantile of χ² with
``m · min(k, w)`` degrees of freedom (m rows): without attack the alarm rate is α at every step.

The attacker holds the rows S of some sensors. Its attack changes the estimate by
``d = x̂_clean − x̂`` (the change of the error ``x − x̂``), so the error is ``e + d`` with e the
clean filter's error (covariance ``P_f``, the filtered steady state, orthogonal to d):

- ``"bias"`` (Mo & Sinopoli: the readings are corrupted): ``y + Γ a`` with ``a`` on S, so
  ``z̃ = z + Δz``, ``Δz = H F d + Γ a`` and ``d ← (F − K H F) d − K Γ a``. d is deterministic
  given the injections; the window's statistic is non-central χ² with non-centrality
  ``Σ_j Δz[j]' Σ⁻¹ Δz[j]``, so the detection probability is exact;
- ``"linear"`` (Guo et al.: the sensor sends its innovations, the attacker replaces them):
  ``z̃ = T z + b`` on S (identity elsewhere), ``b ~ N(0, Σ_b)``, so ``d ← F d + K ((I − T) z − b)``
  and d's covariance ``D ← F D F' + K M K'``, ``M = (I − T) Σ (I − T)' + Σ_b``; the window's
  statistic is a weighted sum of χ²₁ variables (the eigenvalues of ``Σ^{-1/2} Σ̃ Σ^{-1/2}``,
  ``Σ̃ = T Σ T' + Σ_b``), its tail by :func:`fdia_env.detection.gchisq.gchisq_sf`.

Everything is batched over B members (arrays with a leading batch axis): the single env is a
batch of one. Both attacks also run on torch tensors (``xp``, a torch backend of
:mod:`fdia_env.backend`: the native vector env's ``backend="torch"``): the bias attack's χ²
tail by :func:`fdia_env.stealth.torch_ops.ncx2_sf`; the linear attack's filter, covariances and
eigenvalues in torch, its tail (a numerical integral, one per member) by scipy on the
CPU, as numpy computes it. See docs/guide/stealth.md ("Dynamic").
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from fdia_env.backend import NUMPY, Backend
from fdia_env.detection.gchisq import gchisq_sf
from fdia_env.kalman import steady_state
from fdia_env.stealth.tails import ncx2_sf
from fdia_env.systems import LinearSystem

ACTIONS = ("bias", "linear")


@dataclass(frozen=True, eq=False)
class DynamicModel:
    """The filter, the detector's statistics and the attacker's rows (see the module docstring).

    Attributes:
        system: The linear Gaussian system.
        rows: Positions of the attacked rows (of the stacked measurement), protected ones kept.
        free: (len(rows),) bool, the attacked rows that are not protected.
        action: ``"bias"`` or ``"linear"``.
        window: w, the detector's window length.
        a_max: Largest bias per row, in units of that row's innovation standard deviation.
        t_max: Largest change of an entry of T from the identity.
        b_max: Largest standard deviation of b per row, in innovation standard deviations.
    """

    system: LinearSystem
    rows: np.ndarray
    free: np.ndarray
    action: str
    window: int
    a_max: float
    t_max: float
    b_max: float

    def __post_init__(self) -> None:
        sys = self.system
        P, Pf, K = (np.asarray(a, dtype=np.float64) for a in steady_state(sys))
        F, H = np.asarray(sys.F, dtype=np.float64), np.asarray(sys.H, dtype=np.float64)
        Pz = H @ P @ H.T + sys.R
        Pz = (Pz + Pz.T) / 2.0
        Lz = np.linalg.cholesky(Pz)
        Wz = np.linalg.inv(Lz)  # whitening: |Wz z|² = z' Σ⁻¹ z
        values = {
            "F": F,
            "H": H,
            "K": K,
            "P": P,
            "Pf": Pf,
            "Pz": Pz,
            "Wz": Wz,
            "HF": H @ F,
            "Abar": F - K @ H @ F,
            "sigma": np.sqrt(np.diag(Pz))[self.rows],
            "Qh": _psd_sqrt(sys.Q),
            "Rh": np.linalg.cholesky(sys.R),
            "Pfh": _psd_sqrt(Pf),
            "eye": np.eye(H.shape[0]),
            "clean": float(np.trace(Pf)),
        }
        for name, value in values.items():
            object.__setattr__(self, name, value)

    @property
    def n(self) -> int:
        """States."""
        return self.system.n

    @property
    def m(self) -> int:
        """Rows of the stacked measurement."""
        return self.system.nz

    @property
    def action_shape(self) -> tuple[int, ...]:
        """Shape of one action: (|S|,) for a bias, (|S|, |S| + 1) for (T, b)."""
        r = len(self.rows)
        return (r,) if self.action == "bias" else (r, r + 1)

    def thresholds(self, alphas: tuple[float, ...]) -> np.ndarray:
        """(len(alphas), w) τ for each rate and each number of innovations in the window."""
        dof = self.m * np.arange(1, self.window + 1)
        return np.array([stats.chi2.isf(a, dof) for a in alphas])

    def arrays(self, xp: Backend = NUMPY) -> dict[str, Any]:
        """The model's matrices on the backend ``xp`` (numpy: the attributes themselves)."""
        names = ("F", "H", "K", "HF", "Abar", "Wz", "sigma", "Qh", "Rh", "Pfh", "Pz", "rows")
        names += ("free", "eye")
        if xp is NUMPY:
            return {name: getattr(self, name) for name in names}
        cache = self.__dict__.setdefault("_on", {})
        key = (xp.name, str(xp.device))
        if key not in cache:
            cache[key] = {name: xp.asarray(np.asarray(getattr(self, name))) for name in names}
        return cache[key]

    def new_state(self, batch: int, xp: Backend = NUMPY) -> dict[str, Any]:
        """Zero attack effect for ``batch`` members (clean errors drawn by :meth:`restart`)."""
        n, m, w = self.n, self.m, self.window
        linear = self.action == "linear"
        return {
            "k": xp.zeros(batch, dtype=np.int64),
            "e": xp.zeros((batch, n)),
            "d": xp.zeros((batch, n)),
            "D": xp.zeros((batch, n, n)) if linear else xp.zeros((batch, 0, 0)),
            "nc": xp.zeros((batch, w)),
            "mu": xp.zeros((batch, w, m)) if linear else xp.zeros((batch, w, 0)),
            "q": xp.zeros((batch, w)),
        }

    def restart(
        self,
        state: dict[str, Any],
        members: Any,
        rng: Any,
        sampled: bool,
        xp: Backend = NUMPY,
    ) -> None:
        """Start ``members`` (bool (B,)) afresh with no attack effect.

        In sampled dynamics the clean error is drawn from N(0, P_f) (the filter in steady state).
        """
        idx = xp.flatnonzero(members)
        count = int(idx.shape[0])
        if count == 0:
            return
        for key in ("k", "e", "d", "D", "nc", "mu", "q"):
            state[key][idx] = 0
        if sampled:
            state["e"][idx] = self._normal(xp, rng, (count, self.n)) @ self.arrays(xp)["Pfh"].T

    @staticmethod
    def _normal(xp: Backend, rng: Any, shape: tuple[int, ...]) -> Any:
        """Standard normal draws from ``rng`` (numpy's Generator or the device's)."""
        return rng.standard_normal(shape) if xp is NUMPY else xp.normal(rng, shape)

    def step(
        self,
        state: dict[str, np.ndarray],
        actions: np.ndarray,
        alpha: np.ndarray,
        tau: np.ndarray,
        sampled: bool,
        rng: Any,
        free: np.ndarray | None = None,
        xp: Backend = NUMPY,
    ) -> dict[str, Any]:
        """Advance every member one step (in place) and return what it saw.

        Args:
            state: From :meth:`new_state`.
            actions: (B, *action_shape) in [−1, 1].
            alpha: (B,) each member's false-alarm rate.
            tau: (B, w) each member's thresholds (:meth:`thresholds` rows).
            sampled: Draw the noises (else the expected dynamics: no draw).
            rng: numpy Generator for the draws (torch: a ``torch.Generator`` of the device).
            free: (B, |S|) bool, the attacked rows each member's attacker may write this step
                (default :attr:`free`; a defender's protection clears some).
            xp: The arrays' backend (see the module docstring).

        Returns:
            Arrays (B,): ``phi`` (trace of the error covariance given the attack), ``error``
            (realised squared error; ``phi`` in expected dynamics), ``statistic`` (g; its mean
            in expected dynamics), ``threshold``, ``detected``, ``p`` (detection probability),
            ``kl`` (KL divergence of this step's innovation law from the clean one).
        """
        if xp is not NUMPY and free is not None:
            raise ValueError("free (a protecting defender's rows) runs on numpy only")
        mat = self.arrays(xp)
        B = actions.shape[0]
        acts = xp.clip(xp.asarray(actions, dtype=np.float64), -1.0, 1.0)
        k = state["k"] + 1
        slot = (k - 1) % self.window
        rows_b = xp.arange(B)
        d = state["d"]
        if sampled:
            w = self._normal(xp, rng, (B, self.n)) @ mat["Qh"].T
            v = self._normal(xp, rng, (B, self.m)) @ mat["Rh"].T
            z = (state["e"] @ mat["F"].T + w) @ mat["H"].T + v
            state["e"] = state["e"] @ mat["F"].T + w - z @ mat["K"].T
        if self.action == "bias":
            inj = self.injections(acts, free, xp)
            dz = d @ mat["HF"].T + inj
            nc = ((dz @ mat["Wz"].T) ** 2).sum(1)
            state["d"] = d @ mat["Abar"].T - inj @ mat["K"].T
            state["nc"][rows_b, slot] = nc
            kl = 0.5 * nc
            zt = z + dz if sampled else None
            phi = self.clean + (state["d"] ** 2).sum(1)
        else:
            T, Sb = self._linear(acts, free, xp)
            Pz = mat["Pz"]
            ImT = mat["eye"] - T
            M = ImT @ Pz @ _t(ImT) + Sb
            D = state["D"]
            state["D"] = mat["F"] @ D @ mat["F"].T + mat["K"] @ M @ mat["K"].T
            St = T @ Pz @ _t(T) + Sb
            G = mat["Wz"] @ St @ mat["Wz"].T
            G = (G + _t(G)) / 2.0
            if xp is NUMPY:
                mu = np.clip(np.linalg.eigvalsh(G), 0.0, None)
            else:
                mu = xp.clip(xp.eigh(G)[0], 0.0, float("inf"))
            state["mu"][rows_b, slot] = mu
            with np.errstate(divide="ignore"):
                kl = 0.5 * (mu - 1.0 - xp.log(mu)).sum(1)
            if sampled:
                b = xp.sqrt(xp.diagonal(Sb)) * self._normal(xp, rng, (B, self.m))
                zt = xp.einsum("bij,bj->bi", T, z) + b
                state["d"] = d @ mat["F"].T + (z - zt) @ mat["K"].T
            else:
                zt = None
            phi = self.clean + xp.trace(state["D"])
        state["k"] = k
        filled = xp.minimum(k, self.window)
        threshold = tau[rows_b, filled - 1]
        dof = self.m * filled
        if self.action == "bias":
            total = state["nc"].sum(1)
            if xp is NUMPY:
                tail = ncx2_sf(threshold, dof, np.maximum(total, 1e-300))
            else:
                from fdia_env.stealth.torch_ops import ncx2_sf as torch_ncx2_sf

                tail = torch_ncx2_sf(threshold, dof, total)
            p = xp.where(total > 0.0, tail, alpha)
            mean = dof + total
        else:
            weights = state["mu"].reshape(B, -1)
            # the tail's integral runs on the CPU (scipy) on every backend: numpy's own figures
            w_np, x_np, a_np = (xp.to_numpy(v) for v in (weights, threshold, alpha))
            p = xp.asarray(np.array([_chi2_mix_sf(w_np[i], x_np[i], a_np[i]) for i in range(B)]))
            mean = weights.sum(1)
        if sampled:
            state["q"][rows_b, slot] = ((zt @ mat["Wz"].T) ** 2).sum(1)
            statistic = state["q"].sum(1)
            detected = statistic > threshold
            error = ((state["e"] + state["d"]) ** 2).sum(1)
        else:
            statistic = mean
            detected = xp.zeros(B, dtype=np.bool_)
            error = xp.copy(phi)
        return {
            "phi": phi,
            "error": error,
            "statistic": statistic,
            "threshold": threshold,
            "detected": detected,
            "p": xp.clip(p, 0.0, 1.0),
            "kl": kl,
        }

    def _free(self, batch: int, free: np.ndarray | None) -> np.ndarray:
        """(B, |S|) float 0/1: the rows each member's attacker may write."""
        if free is None:
            return np.broadcast_to(self.free.astype(np.float64), (batch, len(self.rows)))
        return np.asarray(free, dtype=np.float64) * self.free

    def _linear(
        self, acts: Any, free: np.ndarray | None = None, xp: Backend = NUMPY
    ) -> tuple[Any, Any]:
        """(B, m, m) T and Σ_b of (B, |S|, |S| + 1) actions (protected rows pass unchanged)."""
        mat = self.arrays(xp)
        B, r = acts.shape[0], len(self.rows)
        allowed = self._free(B, free) if xp is NUMPY else mat["free"].to(acts.dtype)[None, :]
        rows = mat["rows"]
        T = xp.copy(xp.broadcast_to(mat["eye"], (B, self.m, self.m)))
        TS = mat["eye"][:r, :r] + self.t_max * acts[:, :, :r] * allowed[:, :, None]
        T[:, rows[:, None], rows[None, :]] = TS
        Sb = xp.zeros((B, self.m, self.m))
        sb = self.b_max * abs(acts[:, :, r]) * mat["sigma"] * allowed
        Sb[:, rows, rows] = sb**2
        return T, Sb

    def injections(self, actions: Any, free: np.ndarray | None = None, xp: Backend = NUMPY) -> Any:
        """(B, m) the bias injections ``Γ a`` of (B, |S|) actions (``action="bias"``)."""
        mat = self.arrays(xp)
        acts = xp.clip(xp.asarray(actions, dtype=np.float64), -1.0, 1.0)
        inj = xp.zeros((acts.shape[0], self.m))
        allowed = self._free(acts.shape[0], free) if xp is NUMPY else mat["free"].to(acts.dtype)
        inj[:, mat["rows"]] = self.a_max * mat["sigma"] * acts * allowed
        return inj


def _t(x: Any) -> Any:
    """The batch of matrices ``x`` (B, m, m), each transposed (numpy or torch)."""
    return x.swapaxes(-1, -2) if isinstance(x, np.ndarray) else x.transpose(-1, -2)


def chi2_mix_sf(weights: Any, x: float) -> float:
    """``P[Σ_i w_i χ²₁ > x]`` for weights ``w_i ≥ 0`` (independent χ²₁).

    :func:`fdia_env.detection.gchisq.gchisq_sf`: both tails accurate relative to their size at
    any ratio of the weights to x (a large attack's weights put x in the far lower tail, where
    Imhof's oscillating integral does not converge).

    Example:
        >>> round(chi2_mix_sf([1.0, 2.0, 3.0], 10.0), 6)  # 0.173 in 2,000,000 draws
        0.173205
        >>> chi2_mix_sf([1e10, 3e9, 1.0], 12.6) > 1.0 - 1e-4  # x far below the mean
        True
    """
    lam = np.asarray(weights, dtype=np.float64).ravel()
    lam = lam[lam > 0.0]
    if lam.size == 0:
        return float(x < 0.0)
    return float(gchisq_sf(float(x), lam))


def _chi2_mix_sf(weights: np.ndarray, x: float, alpha: float) -> float:
    """:func:`chi2_mix_sf`, with α where every weight is 1 or 0 (no attack: τ's own rate).

    Results are cached by the sorted weights and x: a stationary attack (the same T every
    step, or every member) costs one integral.
    """
    used = np.sort(weights[weights > 0.0])
    if np.all(np.abs(used - 1.0) <= 1e-12):
        return float(alpha)
    return _cached_sf(used.tobytes(), float(x))


@functools.lru_cache(maxsize=4096)
def _cached_sf(key: bytes, x: float) -> float:
    return chi2_mix_sf(np.frombuffer(key, dtype=np.float64), x)


def _psd_sqrt(M: np.ndarray) -> np.ndarray:
    """A square root ``S`` with ``S S' = M`` of a symmetric PSD matrix (eigenvalues clipped)."""
    vals, vecs = np.linalg.eigh((M + M.T) / 2.0)
    return vecs * np.sqrt(np.clip(vals, 0.0, None))
