"""One evaluation loop for every policy: learned, analytic baseline or random.

:func:`evaluate` plays a policy in a Gymnasium view for ``n_episodes`` seeded episodes and
scores it against the analytic reference of :mod:`agents.registry`: the ratio to the optimum in
single-player settings, the exploitability of the policy's mixed strategy in the one-shot game
(``baselines.game.exploitability`` on the exact payoff matrix; for the typed sensor game, where
nature draws the attacker's type, against the exact Bayesian game,
:meth:`baselines.game.BayesianGame.exploitability`).

>>> from baselines.sparse import exhaustive
>>> best = exhaustive("ch4-position", budget=5, horizon=6)
>>> result = evaluate(best.policy(), "fdia_env/SparseAttack-v0", n_episodes=2)
>>> round(result.mean, 10) == round(best.value, 10), round(result.score, 12)
(True, 1.0)
"""

from __future__ import annotations

import inspect
import math
import operator
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
import scipy.stats
from gymnasium import spaces

from agents.registry import Reference, by_gym_id, equilibrium, parallel_of
from fdia_env.actions import check_action
from fdia_env.envs.policy import MaskedPolicyBase, Policy, batch_size

_CHECKED_SPACES = (spaces.Discrete, spaces.Box, spaces.MultiBinary, spaces.MultiDiscrete)


class InvalidActionError(ValueError):
    """A policy returned an action that is not an element of the env's action space."""


def checked_action(policy: Any, env: gym.Env, action: Any) -> Any:
    """``action`` if it is an element of ``env``'s action space (the env's own check).

    The check is the env's (:func:`fdia_env.actions.check_action`, Gymnasium's
    ``Space.contains`` for other spaces): nothing is converted, so a float, a string, a list
    or None for a ``Discrete`` action is refused, not rounded. A ``Discrete`` action is passed
    on as a Python int (the same integer).

    Raises:
        InvalidActionError: Naming the policy, the action and the allowed actions.
    """
    space = env.action_space
    who = str(getattr(getattr(env, "unwrapped", env), "agent", None) or "agent")
    try:
        if isinstance(space, _CHECKED_SPACES):
            check_action(space, action, who)
        elif not space.contains(action):
            raise ValueError(f"{who} action must be an element of {space}, got {action!r}")
    except (ValueError, TypeError) as exc:
        raise InvalidActionError(
            f"policy {policy_name(policy)} returned an action outside the env's action space "
            f"{space}: {exc}"
        ) from None
    if isinstance(space, spaces.Discrete):
        return operator.index(action)
    return action


class RandomPolicy(MaskedPolicyBase):
    """Uniformly random legal actions (SB3 ``predict`` signature, reads ``action_masks``).

    Reproducible per episode: :func:`play` and :func:`play_batched` call
    :meth:`seed_episodes` with each episode's seed, and member ``j`` of a batch draws from the
    generator of episode ``j``, so batched and sequential evaluation play the same episodes.

    Args:
        action_space: The env's action space.
        seed: Seed of the policy's generator until :meth:`seed_episodes` is called.
    """

    def __init__(self, action_space: spaces.Space, seed: int | None = None) -> None:
        self.action_space = action_space
        self.rngs = [np.random.default_rng(seed)]
        if isinstance(action_space, spaces.Discrete):
            self.mask_size = int(action_space.n)  # a mask must cover every action

    @property
    def probs(self) -> np.ndarray | None:
        """Uniform mixed strategy over a Discrete space (None for other spaces)."""
        if isinstance(self.action_space, spaces.Discrete):
            return np.full(int(self.action_space.n), 1.0 / int(self.action_space.n))
        return None

    def seed_episodes(self, seeds: list[int]) -> None:
        """One generator per episode of the next (batch of) episode(s), in member order."""
        self.rngs = [np.random.default_rng([int(s), 0x5EED]) for s in seeds]

    def _draw(self, rng: np.random.Generator, mask: np.ndarray | None) -> Any:
        space = self.action_space
        if isinstance(space, spaces.Discrete):
            legal = np.ones(int(space.n), bool) if mask is None else np.asarray(mask, bool)
            return np.int64(space.start + np.argmax(rng.random(legal.shape) * legal))
        if isinstance(space, spaces.MultiBinary):
            return rng.integers(0, 2, size=space.shape).astype(space.dtype)
        if isinstance(space, spaces.MultiDiscrete):
            return (space.start + rng.integers(0, space.nvec)).astype(space.dtype)
        return rng.uniform(space.low, space.high, space.shape).astype(space.dtype)

    def act(self, observation: Any, deterministic: bool = False, action_masks: Any = None) -> Any:
        """A uniformly random action (among ``action_masks`` when given); batched for (B, d)."""
        batch = batch_size(observation)
        if batch is None:
            return self._draw(self.rngs[0], action_masks)
        if len(self.rngs) != batch:
            raise ValueError(
                f"RandomPolicy has {len(self.rngs)} episode generators for a batch of {batch}: "
                "call seed_episodes() with one seed per member first"
            )
        masks = [None] * batch if action_masks is None else list(action_masks)
        return np.stack([self._draw(r, m) for r, m in zip(self.rngs, masks, strict=True)])


@dataclass(frozen=True)
class Evaluation:
    """What :func:`evaluate` returns.

    Attributes:
        policy: Name of the policy.
        env_id: Gymnasium id of the env (or its class name).
        returns: (n_episodes,) undiscounted episode returns.
        mean: Mean return.
        ci95: Half-width of the 95 % Student-t interval of the mean (NaN for one episode).
        reference: Analytic reference value (optimum or game value), None if none applies.
        reference_name: What the reference is (``"EXS"``, ``"trace-optimal"``, ...).
        score: Single player: ``mean / reference`` (the determinant ratio for log-det
            objectives); game: the exploitability of the policy's mixed strategy (0 at an
            equilibrium). None without a reference.
        score_name: ``"ratio to optimum"``, ``"ratio to best known"`` or ``"exploitability"``.
        strategy: Game only: the policy's mixed strategy over the agent's actions ((S, n), one
            row per type, for an informed attacker of the typed sensor game).
        extras: Further numbers: for games the exploitability relative to the value and the
            best-response value against the env's fixed opponent, when it is a known mix.
    """

    policy: str
    env_id: str
    returns: np.ndarray = field(repr=False)
    mean: float
    ci95: float
    reference: float | None
    reference_name: str | None
    score: float | None
    score_name: str
    strategy: np.ndarray | None = None
    extras: dict[str, float] = field(default_factory=dict)

    @property
    def n_episodes(self) -> int:
        """Number of episodes played."""
        return int(self.returns.size)

    @property
    def ci(self) -> tuple[float, float]:
        """The 95 % confidence interval of the mean return."""
        return self.mean - self.ci95, self.mean + self.ci95

    def score_text(self) -> str:
        """The score as printed in tables (``99.8%`` or ``expl 0.012 (0.15%)``)."""
        if self.score is None:
            return "-"
        if self.score_name == "exploitability":
            rel = self.extras.get("relative_exploitability", math.nan)
            return f"expl {self.score:.4g} ({rel:.2%})"
        text = f"{self.score:.2%}"
        if "ratio_to_bound" in self.extras:  # the optimum is unknown: bracket the true score
            text += f" (≥ {self.extras['ratio_to_bound']:.2%} of the optimum)"
        sfs = self.extras.get("ratio_to_SFS")
        if sfs is not None:
            text += f", {sfs:.2%} of SFS"
        return text

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (NaN as None)."""

        def clean(v: float | None) -> float | None:
            return None if v is None or not math.isfinite(v) else float(v)

        return {
            "policy": self.policy,
            "env_id": self.env_id,
            "n_episodes": self.n_episodes,
            "mean": clean(self.mean),
            "ci95": clean(self.ci95),
            "ci": [clean(c) for c in self.ci],
            "reference": clean(self.reference),
            "reference_name": self.reference_name,
            "score": clean(self.score),
            "score_name": self.score_name,
            "strategy": None if self.strategy is None else self.strategy.tolist(),
            "extras": {k: clean(v) for k, v in self.extras.items()},
        }


def t_interval(returns: np.ndarray, confidence: float = 0.95) -> float:
    """Half-width of the Student-t confidence interval of the mean (NaN for one sample)."""
    n = returns.size
    if n < 2:
        return math.nan
    sem = float(np.std(returns, ddof=1)) / math.sqrt(n)
    return float(scipy.stats.t.ppf(0.5 + confidence / 2, n - 1)) * sem


def policy_name(policy: Any) -> str:
    """A short name: ``"random"`` or the policy's class name."""
    return policy if isinstance(policy, str) else type(policy).__name__


def _accepts_masks(policy: Any) -> bool:
    try:
        return "action_masks" in inspect.signature(policy.predict).parameters
    except (TypeError, ValueError):
        return False


def _as_reference(reference: Reference | float | None, env: gym.Env) -> Reference | None:
    if isinstance(reference, Reference):
        return reference
    if reference is not None:
        return Reference(float(reference), "given")
    entry = by_gym_id(env.spec.id) if env.spec is not None else None
    return entry.reference_of(env) if entry is not None else None


def _masks_fn(env: gym.Env) -> Any:
    """``env``'s ``action_masks`` method, the outermost wrapper's that has one (None: none)."""
    try:
        return env.get_wrapper_attr("action_masks")
    except AttributeError:
        return None


def play(
    policy: Policy | RandomPolicy,
    env: gym.Env,
    n_episodes: int,
    seed: int,
    deterministic: bool = True,
    types: list[int] | None = None,
) -> tuple[np.ndarray, list[Any]]:
    """Episode returns (n_episodes,) and the first action of each episode.

    Episode ``i`` is reset with ``seed + i``; action masks are passed to policies whose
    ``predict`` takes ``action_masks`` (sb3-contrib's MaskablePPO, :class:`RandomPolicy`).
    Each action goes through the env's action check first (:func:`checked_action`): an action
    outside the action space raises :class:`InvalidActionError`, naming the policy.
    ``types``, when given, receives each episode's attacker type where the learning player's
    reset info reports one (the typed sensor game's attacker).
    """
    masks_fn = _masks_fn(env)
    pass_masks = masks_fn is not None and _accepts_masks(policy)
    returns, first_actions = np.zeros(n_episodes), []
    for i in range(n_episodes):
        obs, info = env.reset(seed=seed + i)
        if types is not None and "type" in info:
            types.append(int(info["type"]))
        if hasattr(policy, "seed_episodes"):
            policy.seed_episodes([seed + i])
        done, total, first = False, 0.0, True
        while not done:
            kwargs = {"action_masks": masks_fn()} if pass_masks else {}
            action, _ = policy.predict(obs, deterministic=deterministic, **kwargs)
            if first:
                first_actions.append(action)
                first = False
            action = checked_action(policy, env, action)
            obs, reward, terminated, truncated, _ = env.step(action)
            total += float(reward)
            done = terminated or truncated
        returns[i] = total
    return returns, first_actions


def play_batched(
    policy: Policy | RandomPolicy,
    env: gym.Env,
    n_episodes: int,
    seed: int,
    num_envs: int,
    deterministic: bool = True,
    types: list[int] | None = None,
) -> tuple[np.ndarray, list[Any]]:
    """:func:`play` on the native vector env: ``num_envs`` episodes per batched step.

    The vector env is the one the table of environments gives ``env``'s id
    (:func:`native_vector_env`). On the Kalman-filter engine it is built from ``env``'s own
    two-player env, models and opponent (:class:`fdia_env.vector.FdiaVectorEnv`); rounds of B
    episodes are reset with ``seed + r·B`` (member i gets ``seed + r·B + i``), so episode ``i``
    is the same as in :func:`play` (every such episode has the same length). An env of its own
    (the stealthy attacker's) gets its own vector entry point with the options ``env`` was made
    with; its batch shares one noise generator seeded with ``seed + r·B``, so with sampled noise
    the episodes are other draws of the same distribution than :func:`play`'s. Members whose
    episode ends early are not counted after their end. The policy must accept batched (B, d)
    observations, as SB3 models and the baselines' policies do.
    """
    B = max(1, min(int(num_envs), n_episodes))
    venv = native_vector_env(env, B)
    pass_masks = _accepts_masks(policy) and hasattr(venv, "action_masks")
    returns, first_actions = [], []
    for start in range(0, n_episodes, B):
        obs, info = venv.reset(seed=seed + start)
        if types is not None and "type" in info:
            types.extend(int(t) for t in info["type"])
        if hasattr(policy, "seed_episodes"):
            policy.seed_episodes([seed + start + j for j in range(B)])
        total, done, t = np.zeros(B), np.zeros(B, dtype=bool), 0
        while not done.all():  # every member ends at the same step (a fixed window)
            kwargs = {"action_masks": venv.action_masks()} if pass_masks else {}
            action, _ = policy.predict(obs, deterministic=deterministic, **kwargs)
            action = np.asarray(action)
            if t == 0:
                first_actions.extend(list(action))
            obs, reward, terminated, truncated, _ = venv.step(action)
            total += np.where(done, 0.0, reward)
            done |= terminated | truncated
            t += 1
        returns.append(total)
    venv.close()
    if types is not None:
        del types[n_episodes:]
    return np.concatenate(returns)[:n_episodes], first_actions[:n_episodes]


def native_vector_env(env: gym.Env, num_envs: int) -> Any:
    """The native vector env of ``env`` (a single-agent view) with ``num_envs`` members.

    The Kalman-filter engine's views get :class:`fdia_env.vector.FdiaVectorEnv` over the view's
    own two-player env and opponent; another entry of the table of environments
    (``fdia_env.registration.ENVS``) gets its ``vector`` entry point, called with the options
    ``env`` was made with (``env.spec.kwargs``, so ``env`` must come from ``gymnasium.make``).

    Raises:
        ValueError: Naming ``num_envs`` when the view has no native vector env (the entry's
            ``vector_views``), was not made by ``gymnasium.make`` from a registered id, or was
            made with options its native vector env does not support.
    """
    from fdia_env.envs.parallel import FdiaParallelEnv
    from fdia_env.envs.sequential import SequentialSetEnv, SequentialSubsetEnv
    from fdia_env.registration import ENVS, GYM_IDS

    view = env.unwrapped
    parallel, agent = getattr(view, "parallel", None), getattr(view, "agent", None)
    env_id = env.spec.id if env.spec is not None else None
    module = GYM_IDS[env_id][0] if env_id in GYM_IDS else getattr(parallel, "__module__", None)
    entry = next((e for e in ENVS.values() if e.module == module), None)
    if isinstance(parallel, SequentialSetEnv):  # the sparse attacker's sequential format
        from fdia_env.vector.sequential import SequentialVectorEnv

        return SequentialVectorEnv(parallel, num_envs)
    if isinstance(parallel, SequentialSubsetEnv):  # the sensor game's sequential format
        from fdia_env.vector.sequential_game import SequentialGameVectorEnv

        return SequentialGameVectorEnv(parallel, num_envs, agent=agent, opponent=view.opponent)
    if entry.kalman if entry is not None else isinstance(parallel, FdiaParallelEnv):
        from fdia_env.vector import FdiaVectorEnv

        return FdiaVectorEnv(parallel, num_envs, agent=agent, opponent=view.opponent)
    if entry is None or env_id not in GYM_IDS:
        raise ValueError(
            f"num_envs={num_envs}: the native vector env of {type(view).__name__} needs the env "
            "made by gymnasium.make from its registered id; pass num_envs=None to play the "
            "episodes one by one"
        )
    if not entry.has_vector(agent):
        raise ValueError(
            f"num_envs={num_envs}: {env_id} has no native vector env (only "
            f"{', '.join(entry.views[a] for a in entry.views if entry.has_vector(a)) or 'none'} "
            f"of {entry.name} do); pass num_envs=None to play the episodes one by one"
        )
    if view.opponent is not None and parallel is not None and len(parallel.possible_agents) > 1:
        raise ValueError(
            f"num_envs={num_envs}: {env_id}'s native vector env plays {agent!r} alone, not "
            "against an opponent; pass num_envs=None"
        )
    import importlib

    module_name, _, function = entry.vector.partition(":")
    make = getattr(importlib.import_module(module_name), function)
    try:
        return make(num_envs, **dict(env.spec.kwargs))
    except ValueError as error:
        raise ValueError(
            f"num_envs={num_envs}: {env_id}'s native vector env refuses this env's options "
            f"({error}); pass num_envs=None to play the episodes one by one"
        ) from error


def mixed_strategy(
    policy: Any,
    env: gym.Env,
    seed: int = 0,
    deterministic: bool = True,
    played: list[Any] | None = None,
) -> np.ndarray:
    """The mixed strategy a policy plays in a one-shot game with ``Discrete(n)`` actions.

    In the one-shot game the observation at the decision is the (constant) initial one, so a
    policy is its action distribution there: a fixed mix's ``probs``; for an SB3 model its
    deterministic action (a pure strategy) or, with ``deterministic=False``, its action
    distribution; for any other policy the frequencies of the actions in ``played``.
    """
    from stable_baselines3.common.base_class import BaseAlgorithm

    n = int(env.action_space.n)
    probs = getattr(policy, "probs", None)
    view = getattr(env, "unwrapped", env)
    if hasattr(view, "subset_strategy"):  # the sensor game's sequential format
        return view.subset_strategy(policy, seed, deterministic, played)
    if probs is not None:
        return np.asarray(probs, dtype=np.float64)
    if isinstance(policy, BaseAlgorithm):
        obs, _ = env.reset(seed=seed)
        return _sb3_strategy(policy, obs, n, deterministic)
    if not played:
        raise ValueError("played actions are needed for a policy without probs")
    return np.bincount([int(a) for a in played], minlength=n) / len(played)


def typed_mixed_strategy(
    policy: Any,
    env: gym.Env,
    n_types: int,
    seed: int = 0,
    deterministic: bool = True,
    played: list[Any] | None = None,
    types: list[int] | None = None,
) -> np.ndarray:
    """An informed attacker's (S, n) mixed strategy, one row per type it observes.

    As :func:`mixed_strategy`, type by type: a policy's ``probs`` ((S, n), or (n,) for a
    type-blind one); an SB3 model queried at each type's initial observation (the type forced
    with ``reset(options={"attacker_type": s})``); otherwise the frequencies of ``played``
    among the episodes of each type (``types``), the pooled frequencies for a type never drawn.
    """
    from stable_baselines3.common.base_class import BaseAlgorithm

    n = int(env.action_space.n)
    probs = getattr(policy, "probs", None)
    if probs is not None:
        arr = np.asarray(probs, dtype=np.float64)
        return np.tile(arr, (n_types, 1)) if arr.ndim == 1 else arr
    if isinstance(policy, BaseAlgorithm):
        rows = []
        for s in range(n_types):
            obs, _ = env.reset(seed=seed, options={"attacker_type": s})
            rows.append(_sb3_strategy(policy, obs, n, deterministic))
        return np.stack(rows)
    if not played:
        raise ValueError("played actions are needed for a policy without probs")
    played_a = np.array([int(a) for a in played])
    pooled = np.bincount(played_a, minlength=n) / len(played_a)
    out = np.tile(pooled, (n_types, 1))
    if types is not None and len(types) == len(played_a):
        t = np.asarray(types)
        for s in range(n_types):
            if (t == s).any():
                out[s] = np.bincount(played_a[t == s], minlength=n) / int((t == s).sum())
    return out


def _sb3_strategy(policy: Any, obs: Any, n: int, deterministic: bool) -> np.ndarray:
    """An SB3 model's action distribution at ``obs`` (its action's one-hot if deterministic)."""
    if deterministic or not hasattr(policy.policy, "get_distribution"):
        out = np.zeros(n)
        out[int(policy.predict(obs, deterministic=True)[0])] = 1.0
        return out
    import torch

    obs_t, _ = policy.policy.obs_to_tensor(obs)
    with torch.no_grad():
        dist = policy.policy.get_distribution(obs_t).distribution
    probs = dist.probs.cpu().numpy().reshape(n).astype(np.float64)
    return probs / probs.sum()  # float32 probabilities sum to 1 within 1e-7 only


def _bayesian_score(
    reference: Reference, env: gym.Env, strategy: np.ndarray
) -> tuple[float, dict[str, float]]:
    """Exploitability against the exact Bayesian game (``reference.bayes``)."""
    game = reference.bayes
    sol = game.solution
    value = sol.value
    agent = env.unwrapped.agent
    if agent == "attacker":
        expl = game.exploitability(sol.x, strategy, value).attacker
    else:
        expl = game.exploitability(strategy, sol.y, value).defender
    extras = {"relative_exploitability": expl / abs(value) if value else math.nan}
    opponent_probs = getattr(env.unwrapped.opponent, "probs", None)
    if opponent_probs is not None and parallel_of(env).spec.horizon == 1:
        p = np.asarray(opponent_probs)
        # best response to the fixed opponent: the attacker's (type by type when informed)
        # against the defender's mix p; the defender's against the attacker's strategy p
        if agent == "attacker":
            extras["best_response"] = game.defender_worst_case(p)
        else:
            extras["best_response"] = -game.attacker_worst_case(p)
    return float(expl), extras


def _game_score(
    reference: Reference, env: gym.Env, strategy: np.ndarray
) -> tuple[float, dict[str, float]]:
    from baselines.game import exploitability

    if reference.bayes is not None:
        return _bayesian_score(reference, env, strategy)
    L = reference.payoff
    x_eq, y_eq, value = equilibrium(L)
    parallel = parallel_of(env)
    agent = env.unwrapped.agent
    if agent == "attacker":
        expl = exploitability(L, x_eq, strategy, value).attacker
    else:
        expl = exploitability(L, strategy, y_eq, value).defender
    extras = {"relative_exploitability": expl / abs(value) if value else math.nan}
    opponent_probs = getattr(env.unwrapped.opponent, "probs", None)
    if opponent_probs is not None and parallel.spec.horizon == 1:
        p = np.asarray(opponent_probs)
        # best response to the fixed mix p: the attacker maximises p'L, the defender minimises Lp
        br = float((p @ L).max()) if agent == "attacker" else -float((L @ p).min())
        extras["best_response"] = br
    return float(expl), extras


def evaluate(
    policy: Policy | str,
    env_or_id: gym.Env | str,
    n_episodes: int = 10,
    seed: int = 0,
    reference: Reference | float | None = None,
    deterministic: bool = True,
    num_envs: int | None = None,
    **env_kwargs: Any,
) -> Evaluation:
    """Play ``policy`` for ``n_episodes`` and score it against the analytic reference.

    Args:
        policy: An SB3 model, a baseline policy (anything with SB3's ``predict``) or
            ``"random"`` (uniform over the legal actions).
        env_or_id: A Gymnasium env or id (made with ``env_kwargs``; closed afterwards).
        n_episodes: Episodes to play (episode ``i`` is reset with ``seed + i``).
        seed: Seed of the first episode (and of the random policy).
        reference: The reference value or :class:`~agents.registry.Reference`; by default the
            registry's reference of the env (None when the env's settings have none).
        deterministic: Passed to ``predict`` (mixed baselines sample whatever it says).
        num_envs: Play ``num_envs`` episodes at a time on the native vector env (Monte-Carlo
            evaluation as one batched computation; same episodes as the sequential loop for
            deterministic policies; see :func:`play_batched`); None plays them one by one.
            A view without a native vector env (the table's ``vector_views``) is refused.
        **env_kwargs: Passed to ``gymnasium.make`` when ``env_or_id`` is an id.

    Returns:
        An :class:`Evaluation`. In games the score is the exploitability of the policy's mixed
        strategy on the exact payoff matrix (lower is better); otherwise the ratio to the
        optimum.

    Raises:
        ValueError: For ``n_episodes < 1``, an unknown policy string, env kwargs given with
            an env instance, or ``num_envs`` on a view without a native vector env.
    """
    if isinstance(n_episodes, bool) or not isinstance(n_episodes, int) or n_episodes < 1:
        raise ValueError(f"n_episodes must be a positive integer, got {n_episodes!r}")
    own_env = isinstance(env_or_id, str)
    if not own_env and env_kwargs:
        raise ValueError(f"env_kwargs {sorted(env_kwargs)} need an env id, not an env instance")
    env = gym.make(env_or_id, **env_kwargs) if own_env else env_or_id
    try:
        if isinstance(policy, str):
            if policy != "random":
                raise ValueError(f"policy must be a policy object or 'random', got {policy!r}")
            player: Any = RandomPolicy(env.action_space, seed)
        else:
            player = policy
        view = getattr(env, "unwrapped", env)
        if hasattr(view, "subset_player") and view.is_subset_policy(player):
            if num_envs is not None:
                raise ValueError(
                    f"num_envs={num_envs}: a subset-format mix plays the sequential format one "
                    "episode at a time; pass num_envs=None"
                )
            player = view.subset_player(player)  # a subset mix in the sequential format
        ref = _as_reference(reference, env)
        types: list[int] = []
        if num_envs is None:
            returns, first_actions = play(player, env, n_episodes, seed, deterministic, types)
        else:
            returns, first_actions = play_batched(
                player, env, n_episodes, seed, num_envs, deterministic, types
            )
        mean = float(returns.mean())
        strategy, extras = None, {}
        if ref is None:
            score, score_name = None, "-"
        elif ref.is_game:
            informed = (
                ref.bayes is not None
                and ref.bayes.attacker == "informed"
                and env.unwrapped.agent == "attacker"
            )
            if informed:  # one mix per observed type
                strategy = typed_mixed_strategy(
                    player, env, ref.bayes.n_types, seed, deterministic, first_actions, types
                )
            else:
                strategy = mixed_strategy(player, env, seed, deterministic, first_actions)
            score, extras = _game_score(ref, env, strategy)
            score_name = "exploitability"
        else:
            score = ref.ratio(mean)
            score_name = "ratio to optimum" if ref.exact else "ratio to best known"
            if ref.bound is not None:  # a lower bound on the true score
                extras["ratio_to_bound"] = ref.ratio(mean, ref.bound)
            if ref.heuristic is not None:
                extras[f"ratio_to_{ref.heuristic[0]}"] = ref.ratio(mean, ref.heuristic[1])
        env_id = env.spec.id if env.spec is not None else type(env.unwrapped).__name__
        return Evaluation(
            policy=policy_name(policy),
            env_id=env_id,
            returns=returns,
            mean=mean,
            ci95=t_interval(returns),
            reference=None if ref is None else ref.value,
            reference_name=None if ref is None else ref.name,
            score=score,
            score_name=score_name,
            strategy=strategy,
            extras=extras,
        )
    finally:
        if own_env:
            env.close()
