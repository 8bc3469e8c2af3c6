"""A plan of bias covariances as a policy for ``covariance_attack_v0`` (SB3 signature)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from baselines.sparse.policy import SparsePolicy
from fdia_env._validation import check_int, check_psd
from fdia_env.attacks.covariance import CovarianceAttack
from fdia_env.envs.policy import PolicyBase


def bound_attack(source: Any) -> tuple[CovarianceAttack, int | None]:
    """The bound :class:`CovarianceAttack` of ``source`` and the env's horizon (None if unknown).

    ``source`` is the attack model itself (bound by building an env with it), a
    ``covariance_attack_v0`` parallel env (``env.attack``) or its Gymnasium view, possibly
    wrapped (``env.unwrapped.parallel.attack``).
    """
    if isinstance(source, CovarianceAttack):
        attack, spec = source, None
    else:
        env = getattr(source, "unwrapped", source)
        parallel = getattr(env, "parallel", env)
        attack, spec = getattr(parallel, "attack", None), getattr(parallel, "spec", None)
        if not isinstance(attack, CovarianceAttack):
            raise ValueError(
                "source must be a CovarianceAttack or a covariance_attack_v0 env (parallel or "
                f"Gymnasium view), got {type(source).__name__}"
            )
    if not hasattr(attack, "map"):
        raise ValueError("source's CovarianceAttack is not bound yet: build an env with it first")
    return attack, getattr(spec, "horizon", None)


class CovariancePolicy(PolicyBase):
    """Plays a fixed open-loop plan of bias covariances ``Σ[0], Σ[1], ...`` (one per step).

    Each Σ is turned into the env's action once, at construction, by
    ``attack.sigma_to_action``; the step is recovered from ``observation[0] = steps_left / N``
    (:meth:`step_of` is :class:`~baselines.sparse.SparsePolicy`'s: the two envs share the layout).

    Power per step:

    - ``power_mode="per_step"``: the env injects a² every step whatever Σ's scale, so only the
      plan's directions matter; steps after the plan hold its last Σ (one Σ = the same Σ every
      step). A zero Σ cannot be played in this mode.
    - ``power_mode="budget"``: the plan's *relative* powers ``p_k = tr(Ω Σ[k])`` are played:
      step k spends the fraction ``p_k / Σ_{i≥k} p_i`` of the power left, so the env's budget is
      split over time as in the plan whatever its total; steps after the plan spend nothing.
      A single Σ is a single injection at the first step.

    Args:
        source: A bound :class:`CovarianceAttack`, a ``covariance_attack_v0`` parallel env or
            its Gymnasium view (see :func:`bound_attack`).
        sigmas: (nz, nz) one covariance or (S, nz, nz) one per step, symmetric PSD, e.g.
            ``trace_optimal(...).sigma`` or ``multi_shot(...).sigmas``.
        horizon: Episode length N (default the env's; with a bare attack model, S).

    Example:
        >>> from fdia_env import covariance_attack_v0
        >>> from baselines.covariance import trace_optimal
        >>> env = covariance_attack_v0.parallel_env(scenario="ch2-position", power=3000.0)
        >>> policy = CovariancePolicy(env, trace_optimal("ch2-position").sigma)
        >>> obs, _ = env.reset(seed=0)
        >>> action, _ = policy.predict(obs["attacker"])
        >>> _, rewards, *_ = env.step({"attacker": action})
        >>> round(rewards["attacker"], 1)
        609.9
    """

    step_of = SparsePolicy.step_of

    def __init__(
        self, source: Any, sigmas: Sequence[np.ndarray] | np.ndarray, horizon: int | None = None
    ) -> None:
        attack, env_horizon = bound_attack(source)
        plan = np.asarray(sigmas, dtype=np.float64)
        if plan.ndim == 2:
            plan = plan[None]
        nz = attack.weight.shape[0]
        if plan.ndim != 3 or plan.shape[0] == 0 or plan.shape[1:] != (nz, nz):
            raise ValueError(
                f"sigmas must be one ({nz}, {nz}) covariance or a non-empty sequence of them, "
                f"got shape {plan.shape}"
            )
        for k, sigma in enumerate(plan):
            check_psd(f"sigmas[{k}]", sigma)
        if horizon is None:
            horizon = env_horizon if env_horizon is not None else plan.shape[0]
        self.horizon = check_int("horizon", horizon, minimum=plan.shape[0])
        powers = np.einsum("ab,kba->k", attack.weight, plan)  # p_k = tr(Ω Σ[k])
        if attack.power_mode == "per_step":
            if np.any(powers <= 0.0):
                raise ValueError(
                    "sigmas must all be non-zero in power_mode='per_step' (every step injects "
                    f"a²); powers tr(Ω Σ[k]) = {powers.tolist()}"
                )
            held = plan[np.minimum(np.arange(self.horizon), plan.shape[0] - 1)]
            actions = [attack.sigma_to_action(s) for s in held]
        else:
            if powers.sum() <= 0.0:
                raise ValueError("sigmas must not all be zero: the plan spends no power")
            p = np.concatenate([powers, np.zeros(self.horizon - plan.shape[0])])
            left = np.cumsum(p[::-1])[::-1]  # Σ_{i≥k} p_i
            fractions = np.divide(p, left, out=np.zeros_like(p), where=left > 0.0)
            plan = np.concatenate([plan, np.zeros((self.horizon - plan.shape[0], nz, nz))])
            actions = [attack.sigma_to_action(s, f) for s, f in zip(plan, fractions, strict=True)]
        self.actions = np.stack(actions).astype(np.float32)
        self.actions.setflags(write=False)

    def act(self, observation: Any, deterministic: bool = False) -> np.ndarray:
        """The planned action for the current step (the plan is open loop).

        Args:
            observation: The env's Box observation, unbatched (d,) or batched (B, d).
            deterministic: Ignored (the policy is deterministic).

        Returns:
            A (d,) float32 action for one observation, (B, d) for a batch. Outside the window
            (the terminal observation) the last step's action.
        """
        step = self.step_of(observation)
        return self.actions[np.clip(step, 0, self.horizon - 1)].copy()
