"""One population loop (IBR, FSP, PSRO) on a one-shot two-player matrix game, any oracle.

Each iteration asks a best-response :class:`Oracle` for each side's answer to the other side's
current mixed strategy, adds it to that side's population and updates the mixes:

- ``ibr`` (iterated best response): each side's mix is its latest best response;
- ``fsp`` (fictitious self-play): the uniform average of all its best responses so far;
- ``psro`` (policy-space response oracles, Lanctot et al., NeurIPS 2017): the populations'
  payoffs against each other are measured by playing them in the env (the empirical
  meta-game), and ``baselines.game.solve_zero_sum`` (the LP) gives the meta mix over each.

In the one-shot game a policy acts once, on the constant initial observation, so a learned
deterministic policy is a pure strategy (its action there) and a mix over policies is a mixed
strategy over actions. After every iteration the exploitability of the current pair is
measured exactly on the payoff matrix (:func:`baselines.game.exploitability`).

Oracles are interchangeable: :class:`ExactOracle` (the exact best response on the matrix),
:class:`agents.selfplay.SB3Oracle` (a fresh stable-baselines3 learner per answer) and
:class:`agents.rllib.train.RLlibOracle` (a fresh RLlib PPO learner). :func:`run_population`
is the loop; the driver persists each finished iteration in its ``on_iteration``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from agents.seeding import derived_seed
from baselines.game import exploitability, solve_zero_sum
from fdia_env.envs.policy import PolicyBase, repeat_action

METHODS = ("psro", "fsp", "ibr")
SIDES = ("attacker", "defender")


@dataclass
class BestResponse:
    """One side's answer: a policy with SB3's ``predict``, its pure action, its returns."""

    policy: Any
    action: int
    returns: dict[str, float] | None = None


class Oracle(Protocol):
    """Finds a side's best response to a fixed mixed strategy of the other side."""

    def learn(self, side: str, opponent: np.ndarray, iteration: int) -> BestResponse | None:
        """``side``'s answer to ``opponent``, a mix over the other side's actions.

        Returns None when a stop request cut it short (the iteration is dropped).
        """
        ...

    def save(self, side: str, index: int, response: BestResponse) -> Any:
        """Persist the ``index``-th policy of ``side``; returns its JSON-ready record."""
        ...


@dataclass
class MatrixGame:
    """The game the loop plays: its registry entries, options, exact payoff and sizes.

    Attributes:
        entries: Each side's :class:`agents.registry.Trainable`.
        env_kwargs: The env's options.
        payoff: (m, n) the attacker's payoff, defender actions × attacker actions (for the
            uninformed Bayesian game, ``L̄ = Σ_s p_s L_s``).
        value: The game value (LP).
        exact_meta: PSRO reads its meta-game from ``payoff`` (the pure strategies' exact
            payoffs) instead of playing the populations in the env (:func:`grow_meta`).
    """

    entries: dict[str, Any]
    env_kwargs: dict[str, Any]
    payoff: np.ndarray
    value: float
    exact_meta: bool = False

    @property
    def sizes(self) -> dict[str, int]:
        """Each side's number of actions."""
        m, n = np.shape(self.payoff)
        return {"defender": int(m), "attacker": int(n)}


@dataclass
class PopulationState:
    """What the loop continues from (a new run's: empty populations, uniform mixes).

    Attributes:
        actions: Each side's population as pure strategies (actions), in order.
        policies: Each side's policies (for PSRO's meta-game; may be empty for other methods).
        records: Each side's saved-policy records (:meth:`Oracle.save`).
        meta: (len defender population, len attacker population) empirical meta-game (PSRO).
        x: (m,) the defender's current mix.
        y: (n,) the attacker's current mix.
        history: One record per finished iteration.
        seconds: Training seconds so far.
    """

    actions: dict[str, list[int]]
    policies: dict[str, list[Any]]
    records: dict[str, list[Any]]
    meta: np.ndarray
    x: np.ndarray
    y: np.ndarray
    history: list[dict[str, Any]] = field(default_factory=list)
    seconds: float = 0.0

    @classmethod
    def new(cls, sizes: dict[str, int]) -> PopulationState:
        """Empty populations and uniform mixes."""
        return cls(
            {s: [] for s in SIDES},
            {s: [] for s in SIDES},
            {s: [] for s in SIDES},
            np.zeros((0, 0)),
            np.full(sizes["defender"], 1.0 / sizes["defender"]),
            np.full(sizes["attacker"], 1.0 / sizes["attacker"]),
        )

    def saved(self) -> dict[str, Any]:
        """The loop state as JSON (populations, policy records, meta-game, mixes)."""
        return {
            "populations": self.actions,
            "policies": self.records,
            "meta_payoff": self.meta.tolist(),
            "x": self.x.tolist(),
            "y": self.y.tolist(),
        }


def one_hot(action: int, n: int) -> np.ndarray:
    """The pure strategy ``action`` as an (n,) probability vector."""
    out = np.zeros(n)
    out[action] = 1.0
    return out


def mix_of(population: list[int], weights: np.ndarray, n: int) -> np.ndarray:
    """The mixed strategy over actions of a weighted population of pure strategies."""
    out = np.zeros(n)
    np.add.at(out, population, weights)
    return out / out.sum()


def current_mixes(
    method: str, pops: dict[str, list[int]], n: dict[str, int], meta: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """The defender's and attacker's strategies after an iteration of ``method``.

    ``"ibr"``: each side's last best response; ``"fsp"``: the uniform mix over each population;
    ``"psro"``: the equilibrium of the meta-game ``meta`` (populations × populations) spread
    over the actions.
    """
    if method == "ibr":
        return one_hot(pops["defender"][-1], n["defender"]), one_hot(
            pops["attacker"][-1], n["attacker"]
        )
    if method == "fsp":
        weights = {side: np.ones(len(pops[side])) for side in ("defender", "attacker")}
    else:
        sx, sy, _ = solve_zero_sum(meta)
        weights = {"defender": sx, "attacker": sy}
    return (
        mix_of(pops["defender"], weights["defender"], n["defender"]),
        mix_of(pops["attacker"], weights["attacker"], n["attacker"]),
    )


def initial_action(policy: Any, entry: Any, env_kwargs: dict[str, Any]) -> int:
    """The pure strategy of a policy: its deterministic action at the initial state.

    In the sequential format (a subset built one sensor per decision) it is the index of the
    subset the policy builds in the first round, played deterministically from ``reset(seed=0)``.
    """
    with entry.make_resolved(env_kwargs) as env:
        view = env.unwrapped
        if hasattr(view, "subset_strategy"):
            return int(np.argmax(view.subset_strategy(policy, seed=0, deterministic=True)))
        obs, _ = env.reset(seed=0)
    return int(policy.predict(obs, deterministic=True)[0])


def empirical_payoff(
    attacker: Any,
    defender: Any,
    entry: Any,
    env_kwargs: dict[str, Any],
    n_episodes: int,
    seed: int,
) -> float:
    """The attacker's mean return when the two policies play each other in the env.

    In the typed sensor game (``types=``) the mean is exact over nature's draw: one episode per
    type, forced with ``reset(options={"attacker_type": s})``, weighted by the priors (the
    one-shot expected-dynamics payoff of two deterministic policies does not vary otherwise).
    """
    from agents.evaluate import evaluate

    with entry.view(opponent=defender, **env_kwargs) as env:
        priors = getattr(env.unwrapped.parallel.attack, "priors", None)
        if priors is None:
            return evaluate(attacker, env, n_episodes, seed, reference=None).mean
        total = 0.0
        for s, p in enumerate(priors):
            obs, _ = env.reset(seed=seed, options={"attacker_type": s})
            action, _ = attacker.predict(obs, deterministic=True)
            _, reward, *_ = env.step(int(action))
            total += float(p) * float(reward)
        return total


def grow_meta(
    meta: np.ndarray,
    policies: dict[str, list[Any]],
    attacker_entry: Any,
    env_kwargs: dict[str, Any],
    seed: int,
    actions: dict[str, list[int]] | None = None,
) -> np.ndarray:
    """Extend the empirical meta-payoff (defender rows, attacker columns) to the new policies.

    Only the new row and column are played (one episode per pair: the payoff of two
    deterministic policies in the expected-dynamics game is exact; sampled dynamics would
    need more). In the sequential format each side is played as its pure strategy
    (``actions``: the subset its answer builds) in the subset format, where every subset
    pair pays as in the sequential one.
    """
    if env_kwargs.get("action") == "sequential":
        if actions is None:
            raise ValueError("the sequential format's meta-game needs both sides' actions")
        policies = {side: [ConstantPolicy(a) for a in actions[side]] for side in SIDES}
        env_kwargs = {k: v for k, v in env_kwargs.items() if k != "illegal_action"}
        env_kwargs["action"] = "subset"
    m, k = len(policies["defender"]), len(policies["attacker"])
    out = np.zeros((m, k))
    out[: meta.shape[0], : meta.shape[1]] = meta
    for i in range(m):
        for j in range(k):
            if i < meta.shape[0] and j < meta.shape[1]:
                continue
            out[i, j] = empirical_payoff(
                policies["attacker"][j], policies["defender"][i], attacker_entry, env_kwargs, 1,
                seed,
            )  # fmt: skip
    return out


def at_fixed_point(method: str, actions: dict[str, list[Any]]) -> bool:
    """Whether the last iteration's answers leave the loop where it was (it has converged).

    PSRO: both answers were already in their populations, so the meta-game, the mixes and the
    next answers repeat (with exact answers: double oracle's end, an equilibrium of the full
    game). IBR: both answers repeat the previous ones (a pure equilibrium). FSP's average moves
    with every answer: never.
    """
    if method == "psro":
        return all(actions[s] and actions[s][-1] in actions[s][:-1] for s in SIDES)
    if method == "ibr":
        return all(len(actions[s]) > 1 and actions[s][-1] == actions[s][-2] for s in SIDES)
    return False


def report_line(rec: dict[str, Any]) -> str:
    """One iteration's line: best responses, their gaps, exploitabilities, NashConv."""
    return (
        f"iter {rec['iteration']:3d}  steps {rec['timesteps']:8d}  "
        f"BR attacker {rec['br_attacker']} (gap {rec['br_gap_attacker']:.3g})  "
        f"BR defender {rec['br_defender']} (gap {rec['br_gap_defender']:.3g})  "
        f"expl def {rec['defender']:.4f} att {rec['attacker']:.4f}  "
        f"NashConv {rec['nash_conv']:.4f} ({rec['relative_nash_conv']:.2%} of value)"
    )


class ConstantPolicy(PolicyBase):
    """Plays ``action`` whatever it observes (SB3's ``predict``): a pure strategy."""

    def __init__(self, action: int) -> None:
        self.action = int(action)

    def act(self, observation: Any, deterministic: bool = False) -> np.ndarray:
        """``action`` (a 0-d array), or (B,) of it for a batched observation."""
        return repeat_action(np.array(self.action), observation)


@dataclass
class LearnedOracle:
    """What every learned oracle shares: the run's settings, its folder and the trainables.

    Subclasses (:class:`agents.selfplay.SB3Oracle`, :class:`agents.selfplay.TorchPPOOracle`,
    :class:`agents.rllib.train.RLlibOracle`) add their learner's settings and write
    :meth:`Oracle.learn` and :meth:`Oracle.save` with :meth:`seed` and :meth:`policy_path`.

    Attributes:
        cfg: The run's :class:`~agents.config.GameConfig`.
        run_dir: The run folder.
        entries: Each side's :class:`~agents.registry.Trainable`.
        env_kwargs: The env's options.
    """

    cfg: Any
    run_dir: Path
    entries: dict[str, Any]
    env_kwargs: dict[str, Any]

    def seed(self, side: str, iteration: int) -> int:
        """The seed of ``side``'s answer in ``iteration``, derived from the run's seed."""
        return derived_seed(self.cfg.run.seed, 1000 * iteration + SIDES.index(side))

    def policy_path(self, side: str, index: int, suffix: str = ".json") -> Path:
        """Where the ``index``-th policy of ``side`` is saved: ``policies/<side>_<index>``."""
        return self.run_dir / "policies" / f"{side}_{index}{suffix}"


class ExactOracle:
    """The exact best response on the payoff matrix (ties: the lowest action).

    The attacker maximises ``x @ L``, the defender minimises ``L @ y``. With it the loop is the
    textbook IBR / FSP / double oracle (PSRO with exact answers), a reference for learned
    oracles and a fast check of the loop itself.
    """

    def __init__(self, payoff: np.ndarray) -> None:
        self.payoff = np.asarray(payoff, dtype=np.float64)

    def learn(self, side: str, opponent: np.ndarray, iteration: int) -> BestResponse:
        """The pure action that best answers ``opponent``."""
        if side == "attacker":
            action = int(np.argmax(opponent @ self.payoff))
        else:
            action = int(np.argmin(self.payoff @ opponent))
        return BestResponse(ConstantPolicy(action), action)

    def save(self, side: str, index: int, response: BestResponse) -> Any:
        """A pure strategy is its own record: the action."""
        return response.action


def run_population(
    method: str,
    oracle: Oracle,
    game: MatrixGame,
    state: PopulationState,
    iterations: int,
    seed: int,
    steps_per_iteration: int = 0,
    stop: Callable[[], bool] | None = None,
    on_iteration: Callable[[dict[str, Any], PopulationState], None] | None = None,
    progress: Any = None,
) -> list[dict[str, Any]]:
    """Iterate ``method`` from ``state`` (in place) up to ``iterations`` finished iterations.

    Args:
        method: ``"psro"``, ``"fsp"`` or ``"ibr"``.
        oracle: Each side's best responses.
        game: The matrix game.
        state: The populations and mixes to continue from; updated after each iteration.
        iterations: Iterations in all (the state's finished ones included).
        seed: The run's seed (PSRO's meta-game episodes).
        steps_per_iteration: Env steps of one best response (for the records' ``timesteps``:
            two per iteration).
        stop: Polled before each iteration; True ends the loop.
        on_iteration: Called with each finished iteration's record and the state (to persist
            and report it).
        progress: Wraps the iteration range (a progress bar), or None.

    Returns:
        The history of all finished iterations (``state.history``).

    Raises:
        ValueError: For an unknown method.
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; valid methods: {', '.join(METHODS)}")
    L, value, n = game.payoff, game.value, game.sizes
    start = time.perf_counter() - state.seconds
    steps = range(len(state.history) + 1, iterations + 1)
    for it in steps if progress is None else progress(steps):
        if stop is not None and stop():
            break
        opponents = {"attacker": state.x, "defender": state.y}  # each answers the other's mix
        new: dict[str, BestResponse] = {}
        for side in SIDES:
            response = oracle.learn(side, opponents[side], it)
            if response is None:
                break
            new[side] = response
        if len(new) < len(SIDES):  # cut short by a stop request: the iteration is dropped
            break
        x, y = state.x, state.y
        for side in SIDES:
            state.records[side].append(oracle.save(side, len(state.actions[side]), new[side]))
            state.policies[side].append(new[side].policy)
            state.actions[side].append(new[side].action)
        # how far each answer is from an exact best response to the mix it answered
        gap_att = float((x @ L).max() - (x @ L)[state.actions["attacker"][-1]])
        gap_def = float((L @ y)[state.actions["defender"][-1]] - (L @ y).min())
        if method == "psro" and game.exact_meta:
            state.meta = np.asarray(L)[np.ix_(state.actions["defender"], state.actions["attacker"])]
        elif method == "psro":
            state.meta = grow_meta(
                state.meta,
                state.policies,
                game.entries["attacker"],
                game.env_kwargs,
                seed,
                state.actions,
            )
        state.x, state.y = current_mixes(method, state.actions, n, state.meta)
        e = exploitability(L, state.x, state.y, value)
        state.seconds = time.perf_counter() - start
        rec: dict[str, Any] = {
            "iteration": it,
            "timesteps": 2 * it * steps_per_iteration,
            "train_seconds": round(state.seconds, 3),
            "defender": e.defender,
            "attacker": e.attacker,
            "nash_conv": e.nash_conv,
            "relative_nash_conv": e.nash_conv / abs(value),
            "br_attacker": state.actions["attacker"][-1],
            "br_defender": state.actions["defender"][-1],
            "br_gap_attacker": gap_att,
            "br_gap_defender": gap_def,
        }
        if all(new[side].returns is not None for side in SIDES):
            rec["agent_returns"] = {
                side: new[side].returns.get(side, float("nan")) for side in SIDES
            }
        rec.update(x=state.x.tolist(), y=state.y.tolist())
        state.history.append(rec)
        if on_iteration is not None:
            on_iteration(rec, state)
    return state.history
