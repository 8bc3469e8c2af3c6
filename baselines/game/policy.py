"""An equilibrium mixed strategy as a policy (stable-baselines3 ``predict`` signature)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from baselines.game.lp import as_strategy
from fdia_env._validation import check_int
from fdia_env.attacks.subsets import subsets
from fdia_env.envs.opponents import FixedMix
from fdia_env.envs.policy import SampledPolicyBase, observation_array


class MixedStrategyPolicy(FixedMix):
    """Plays a fixed mixed strategy over ``Discrete(2^M − 1)`` subset actions.

    A :class:`~fdia_env.envs.opponents.FixedMix` (sampling, seeding, ``mode``, batched
    ``predict``) that validates like the LP solvers and can be built from a subset mapping.

    Action ``j`` is the j-th subset of :func:`fdia_env.attacks.subsets.subsets` (size, then
    lexicographic), the same indices as the payoff matrix's rows and columns and as the actions of
    ``fdia_env.sensor_game_v0``, where it can be the fixed opponent of the single-agent views
    (``gymnasium.make("fdia_env/SensorGameDefender-v0", opponent=policy)``). The policy ignores
    the observation except to tell a single observation from a batch.

    ``deterministic`` is ignored on purpose: a mixed equilibrium strategy is an equilibrium only
    when it is sampled, and SB3's ``evaluate_policy`` passes ``deterministic=True`` by default,
    which would otherwise turn it into an exploitable pure strategy. Reproducibility comes from
    the seeded generator instead (``seed`` here or :meth:`reset`); :meth:`mode` gives the
    argmax pure strategy for whoever wants it.

    Args:
        probs: (K,) probabilities ≥ 0 summing to 1 (within 1e-9; renormalised).
        seed: Seed of the policy's own ``numpy.random.Generator``.

    Example:
        >>> policy = MixedStrategyPolicy([0, 0, 0, 0, 0, 0.4, 0.6], seed=0)
        >>> action, state = policy.predict(np.zeros(3))
        >>> int(action) in (5, 6), state is None
        (True, True)
        >>> policy.predict(np.zeros((4, 3)))[0].shape  # a batch of 4 observations
        (4,)
    """

    def __init__(self, probs: Any, seed: int | None = None) -> None:
        arr = np.asarray(probs, dtype=np.float64)
        if arr.ndim != 1 or arr.size == 0:
            raise ValueError(f"probs must be a non-empty 1-D probability vector, got {probs!r}")
        super().__init__(as_strategy(arr, arr.size, "probs"), seed)

    @classmethod
    def from_subsets(
        cls, support: Mapping[tuple[int, ...], float], M: int, seed: int | None = None
    ) -> MixedStrategyPolicy:
        """The policy of a ``{subset: probability}`` mix (e.g. a double oracle's) over M sensors."""
        M = check_int("M", M, minimum=1)
        index = {s: j for j, s in enumerate(subsets(M))}
        probs = np.zeros(len(index))
        for s, p in support.items():
            key = tuple(sorted(int(i) for i in s))
            if key not in index:
                raise ValueError(f"support has {s!r}, not a non-empty subset of {M} sensors")
            probs[index[key]] += p
        return cls(probs, seed)


class TypedMixedStrategyPolicy(SampledPolicyBase):
    """An informed attacker's strategy: mix ``probs[s]`` when its type is s.

    The type is read from the observation of ``sensor_game_v0(types=..., attacker_model=
    "informed")``, whose last S entries are the type's one-hot; batched (B, d) observations
    give (B,) actions, each member by its own type. ``deterministic`` is ignored (see
    :class:`MixedStrategyPolicy`).

    Args:
        probs: (S, n) one probability vector per type (rows ≥ 0 summing to 1).
        seed: Seed of the policy's own generator.

    Example:
        >>> policy = TypedMixedStrategyPolicy([[1, 0, 0], [0, 0.5, 0.5]], seed=0)
        >>> int(policy.predict(np.array([0.3, 1.0, 0.0]))[0])  # type 0
        0
        >>> policy.predict(np.array([[0.3, 0.0, 1.0], [0.3, 1.0, 0.0]]))[0].tolist()
        [1, 0]
    """

    def __init__(self, probs: Any, seed: int | None = None) -> None:
        arr = np.asarray(probs, dtype=np.float64)
        if arr.ndim != 2 or 0 in arr.shape:
            raise ValueError(f"probs must be an (S, n) array, one strategy per type, got {probs!r}")
        rows = np.stack([as_strategy(r, arr.shape[1], f"probs[{s}]") for s, r in enumerate(arr)])
        self.probs = rows / rows.sum(axis=1, keepdims=True)
        self.probs.setflags(write=False)
        self.n_types, self.n_actions = self.probs.shape
        self._cdf = np.cumsum(self.probs, axis=1)
        super().__init__(seed)

    def act(self, observation: Any, deterministic: bool = False) -> Any:
        """An action drawn from the observed type's mix (``deterministic`` is ignored)."""
        obs = observation_array(observation, dtype=np.float64)
        if obs.ndim not in (1, 2) or obs.shape[-1] < self.n_types:
            raise ValueError(
                f"observation must end with the {self.n_types}-entry type one-hot, got shape "
                f"{obs.shape}"
            )
        batch = np.atleast_2d(obs)
        s = np.argmax(batch[:, -self.n_types :], axis=1)
        u = self.rng.random(len(s))
        a = np.array(
            [np.searchsorted(self._cdf[k], ui, side="right") for k, ui in zip(s, u, strict=True)]
        )
        a = np.minimum(a, self.n_actions - 1).astype(np.int64)
        return np.int64(a[0]) if obs.ndim == 1 else a
