"""The envs an agent can be trained on, their scenarios, algorithms and analytic references.

One :class:`Trainable` per (env, learning agent): the Gymnasium id of its single-agent view,
the scenarios it is set up for (with their default env kwargs), the stable-baselines3
algorithms that fit its action space (the first is the default) and the function that gives the
analytic optimum of a built env, against which :func:`agents.evaluate.evaluate` scores a policy.
Adding an env is one :func:`register` call (e.g. ``detection_game_v0`` with the OBDD threshold
as its reference).

>>> entry = get("sparse_attack_v2")
>>> entry.gym_id, entry.algorithms
('fdia_env/SparseAttack-v2', ('MaskablePPO', 'PPO', 'A2C', 'DQN'))
>>> round(entry.reference_of(entry.make()).value, 4)
0.0328
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

import fdia_env  # noqa: F401 - registers the Gymnasium ids
from agents.config import GRID_PRESETS, SCENARIO_DEFAULTS, SPARSE_ENVS
from fdia_env.envs.parallel import FdiaParallelEnv
from fdia_env.envs.sequential import SequentialSetEnv
from fdia_env.registration import get_env

AGENTS = ("attacker", "defender")

# Every algorithm the training code knows; a Trainable lists the ones that fit its action space.
ALGORITHMS = ("PPO", "MaskablePPO", "A2C", "DQN", "SAC")
DISCRETE_ALGORITHMS = ("PPO", "A2C", "DQN")
MASKED_ALGORITHMS = ("MaskablePPO", *DISCRETE_ALGORITHMS)
BOX_ALGORITHMS = ("SAC", "PPO", "A2C")

# EXS is exact but costs C(M·N, c) evaluations (~10⁷/s); above this the reference is the best
# of the polynomial heuristics ("best known heuristic where the optimum is out of reach").
EXS_MAX_SETS = 20_000_000
BNB_TIME_LIMIT = 60.0  # seconds of branch and bound for a sparse reference past EXS


@dataclass(frozen=True)
class Reference:
    """The analytic answer a learned policy is scored against.

    Attributes:
        value: The optimal episode return (for games: the game value, attacker's payoff).
        name: What it is (``"EXS"``, ``"trace-optimal"``, ``"game value (LP)"``, ...).
        objective: ``"trace"`` or ``"logdet"``; the single-player score is ``return / value``
            for ``"trace"`` and the determinant ratio ``exp(return − value)`` for ``"logdet"``.
        exact: False when the value is the best known heuristic rather than the optimum.
        payoff: (m, n) game payoff ``L[D, A]`` (defender rows) for games; None otherwise.
        policy: The analytic answer as a policy for the view (SB3 ``predict``), if there is one:
            played in the env it returns ``value`` (in a game, in expectation).
        cost: The returns are negative costs (a defender's): the score is then
            ``value / return`` (optimal cost over learned cost), at most 1 like the others.
        bound: When ``exact`` is False: a certified upper bound on the optimum (branch and
            bound), in the units of ``value``; a return's ratio to it is a lower bound on its
            true score.
        heuristic: ``(name, value)`` of a greedy answer (SFS) to compare with where the optimum
            is unknown.
        bayes: The incomplete-information sensor game
            (:class:`~baselines.game.bayesian.BayesianGame`) when nature draws the attacker's
            type: policies are scored by exploitability against it. ``payoff`` is then its
            ``L̄`` in the uninformed model (a matrix game over the attacker's actions) and None
            in the informed one (whose attacker strategies are per type).
    """

    value: float
    name: str
    objective: str = "trace"
    exact: bool = True
    payoff: np.ndarray | None = field(default=None, repr=False)
    policy: Any = field(default=None, repr=False, compare=False)
    cost: bool = False
    bound: float | None = None
    heuristic: tuple[str, float] | None = None
    bayes: Any = field(default=None, repr=False, compare=False)

    @property
    def is_game(self) -> bool:
        """Whether the score is an exploitability (a game) rather than a ratio."""
        return self.payoff is not None or self.bayes is not None

    def matrix_game(self) -> np.ndarray:
        """The payoff of a matrix game over the two players' actions, for self-play.

        Raises:
            ValueError: For a reference that is no such game (the informed-attacker Bayesian
                game: its attacker's strategies depend on the type it observes).
        """
        if self.payoff is None:
            why = (
                "the informed-attacker Bayesian game is not a matrix game over the attacker's "
                "actions (its strategy depends on the type it observes); use "
                "attacker_model='uninformed'"
                if self.bayes is not None
                else f"{self.name} is not a game"
            )
            raise ValueError(why)
        return self.payoff

    def ratio(self, mean_return: float, value: float | None = None) -> float:
        """Single-player score: the return as a fraction of the optimum (or of ``value``)."""
        value = self.value if value is None else value
        if self.objective == "logdet":
            return math.exp(mean_return - value)  # det ratio
        if self.cost:
            return value / mean_return  # both negative: optimal cost / learned cost
        return mean_return / value


def parallel_of(env: gym.Env) -> FdiaParallelEnv | SequentialSetEnv:
    """The :class:`FdiaParallelEnv` behind a (possibly wrapped) fdia_env Gymnasium view.

    For the sparse attack's ``action="sequential"`` it is the format's wrapper, which has the
    wrapped env's ``spec``, ``scenario``, ``system`` and ``attack``.
    """
    parallel = getattr(env.unwrapped, "parallel", None)
    if not isinstance(getattr(parallel, "inner", parallel), FdiaParallelEnv):
        raise ValueError(f"not an fdia_env single-agent view: {env.unwrapped!r}")
    return parallel


# ----------------------------------------------------------------------------------------------
# References: f(parallel env) -> Reference, or None where the env's settings leave no analytic
# answer comparable with the episode return (e.g. shaped rewards, a non-steady start).


def _plan_policy(result: Any, action: str) -> Any:
    """The solver's plan as a policy in the env's format.

    None in ``"single"``: one sensor a step cannot play every plan, so that row is not scored
    by playing.
    """
    if action == "sequential-plan":  # the sequential format's plan-first order
        from fdia_env.envs.sequential import PlanOrderPolicy

        return PlanOrderPolicy.from_result(result)
    return None if action == "single" else result.policy(action)


def sparse_reference(env: FdiaParallelEnv) -> Reference | None:
    """EXS for the env's scenario, budget, horizon and objective, or a certified answer.

    ``baselines.sparse.exhaustive`` when its ``C(M·N, c)`` sets are within
    :data:`EXS_MAX_SETS`; else ``branch_and_bound`` with :data:`BNB_TIME_LIMIT`: its optimum
    when proved, otherwise its best set (at least as good as SFS-SS and DP) with the certified
    upper bound and SFS's value, so a learned policy is scored against the best known answer,
    the bound (a lower bound on its true score) and the greedy heuristic.
    """
    from baselines.sparse import branch_and_bound, exhaustive, sfs

    # the plan is played in the env's own action format (one sensor per decision when sequential)
    action = "sequential" if isinstance(env, SequentialSetEnv) else env.attack.format
    if isinstance(env, SequentialSetEnv) and env.plan_first:
        action = "sequential-plan"
    spec = env.spec
    if spec.reward_mode != "terminal" or spec.warmup != "steady":
        return None  # the solvers' objective is Φ at the window end from steady state
    args = (env.scenario, env.attack.budget, spec.horizon, spec.objective)
    if math.comb(env.system.M * spec.horizon, env.attack.budget) <= EXS_MAX_SETS:
        best = exhaustive(*args)
        return Reference(best.value, "EXS", spec.objective, policy=_plan_policy(best, action))
    proof = branch_and_bound(*args, time_limit=BNB_TIME_LIMIT)
    greedy = ("SFS", sfs(*args).value)
    if proof.proved_optimal:
        name = "B&B (certified optimum)"
        return Reference(
            proof.value, name, spec.objective, policy=_plan_policy(proof, action), heuristic=greedy
        )
    return Reference(
        proof.value,
        "best known (B&B incumbent)",
        spec.objective,
        False,
        policy=_plan_policy(proof, action),
        bound=proof.upper_bound,
        heuristic=greedy,
    )


def covariance_reference(env: FdiaParallelEnv) -> Reference | None:
    """``trace_optimal`` (or ``det_optimal`` for log-det) of a single injection at steady state."""
    from baselines.covariance import det_optimal, trace_optimal

    spec, attack = env.spec, env.attack
    if spec.horizon != 1 or spec.warmup != "steady" or spec.reward_mode == "shaped":
        return None  # the closed forms are for one injection, paid Φ of that step
    if spec.objective == "trace":
        best = trace_optimal(env.scenario, attack.power, attack.structure, attack.weight)
        return Reference(best.value, "trace-optimal", "trace", policy=best.policy(env))
    if attack.structure != "full":
        return None  # water-filling is the full-structure optimum only
    best = det_optimal(env.scenario, attack.power, weight=attack.weight)
    return Reference(best.value, "det-optimal", "logdet", policy=best.policy(env))


def game_reference(env: FdiaParallelEnv, agent: str = "attacker") -> Reference | None:
    """The LP value of the one-shot sensor-selection game, with its payoff matrix.

    The policy is ``agent``'s equilibrium mix; for the defender the value is its own return −v.
    """
    from baselines.game import MixedStrategyPolicy

    if env.spec.horizon != 1:
        return None  # repeated rounds: no exact matrix-game reference here
    if getattr(env.attack, "types", None) is not None:
        return bayesian_reference(env, agent)
    attack = env.attack
    L, x, y, value = _solved_game(
        env.scenario, attack.power, attack.allocation, attack.max_subset_size
    )
    if agent == "defender":
        policy = MixedStrategyPolicy(x, seed=0)
        return Reference(-value, "game value (LP)", "trace", True, L, policy)
    return Reference(value, "game value (LP)", "trace", True, L, MixedStrategyPolicy(y, seed=0))


_EQUILIBRIA: dict[tuple, tuple[np.ndarray, np.ndarray, float]] = {}
_MAX_EQUILIBRIA = 8


def equilibrium(L: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """:func:`baselines.game.solve_zero_sum` of ``L``, solved once per matrix (read-only).

    Every evaluation of a game policy scores it against the same payoff matrix; HiGHS takes
    seconds on the 1,023 × 1,023 games, so the equilibrium is kept for the last few matrices,
    keyed by their contents (a BLAKE2 digest of the bytes: a matrix changed in place is solved
    again).
    """
    from baselines.game import solve_zero_sum

    L = np.ascontiguousarray(L, dtype=np.float64)
    key = (L.shape, hashlib.blake2b(L.view(np.uint8), digest_size=32).digest())
    hit = _EQUILIBRIA.get(key)
    if hit is None:
        x, y, value = solve_zero_sum(L)
        x.setflags(write=False)
        y.setflags(write=False)
        hit = (x, y, value)
        if len(_EQUILIBRIA) >= _MAX_EQUILIBRIA:
            _EQUILIBRIA.pop(next(iter(_EQUILIBRIA)))
        _EQUILIBRIA[key] = hit
    return hit


_GAMES: dict[tuple[str, float, str, int | None], tuple[Any, tuple]] = {}
_MAX_GAMES = 8
_BAYESIAN: dict[tuple, tuple[Any, Any]] = {}


def _cached_bayesian_game(env: FdiaParallelEnv, build: Callable[[Any], Any]) -> Any:
    """``build(env)``: the typed game's BayesianGame, kept for the last few games.

    The game's LP solution (a cached property) is kept with it: on game-m10 with an informed
    attacker the LP takes seconds, and a run asks for the game for every view it scores. A hit
    is used only for the same scenario (:func:`_same_scenario`) and the same typed attack
    (types, priors, attacker model, power, largest subset).
    """
    attack = env.attack
    key = (
        str(getattr(env.scenario, "name", id(env.scenario))),
        tuple(attack.types),
        tuple(float(p) for p in attack.priors),
        str(attack.attacker_model),
        float(attack.power),
        attack.max_subset_size,
    )
    hit = _BAYESIAN.get(key)
    if hit is not None and _same_scenario(hit[0], env.scenario):
        return hit[1]
    game = build(env)
    if len(_BAYESIAN) >= _MAX_GAMES:
        _BAYESIAN.pop(next(iter(_BAYESIAN)))
    _BAYESIAN[key] = (env.scenario, game)
    return game


def _equal(a: Any, b: Any) -> bool:
    """Equal values, arrays compared entry by entry (mappings and sequences by their items)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.shape(a) == np.shape(b) and bool(np.array_equal(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(_equal(x, y) for x, y in zip(a, b, strict=True))
    return bool(a == b)


def _same_scenario(a: Any, b: Any) -> bool:
    """Whether two scenarios are one game's: the same object, or equal fields and systems."""
    if a is b:
        return True
    if type(a) is not type(b) or not dataclasses.is_dataclass(a):
        return False
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.name == "system":
            if type(x) is not type(y) or not all(
                _equal(getattr(x, k, None), getattr(y, k, None))
                for k in ("F", "Q", "H", "R", "Gu", "T", "name")
            ):
                return False
        elif not _equal(x, y):
            return False
    return True


def _solved_game(
    scenario: Any, power: float, allocation: str, max_subset_size: int | None = None
) -> tuple:
    """``(L, x, y, value)`` of the sensor game, kept for the last few scenarios solved.

    A grid preset's game (596 × 595 on grid-ieee14) takes seconds to build and solve, and a
    run asks for it for every view it scores; a game whose matrix the benchmark stores
    (:func:`fdia_env.tasks.payoffs.stored_payoff`: IEEE 118, minutes to build) is read.
    Keyed by the scenario's name and the game's options; a hit is used only for a scenario
    equal to the one it was solved for (:func:`_same_scenario`: a preset rebuilt by every env
    is the same scenario, not the same object).
    """
    from baselines.game import payoff_matrix

    key = (str(getattr(scenario, "name", id(scenario))), float(power), str(allocation))
    key += (max_subset_size,)
    hit = _GAMES.get(key)
    if hit is not None and _same_scenario(hit[0], scenario):
        return hit[1]
    from fdia_env.tasks.payoffs import stored_payoff

    L = stored_payoff(scenario, power, allocation, max_subset_size)  # the IEEE 118 game's
    if L is None:
        L = payoff_matrix(scenario, power, allocation, max_subset_size)
        L.setflags(write=False)
    solved = (L, *equilibrium(L))
    if len(_GAMES) >= _MAX_GAMES:
        _GAMES.pop(next(iter(_GAMES)))
    _GAMES[key] = (scenario, solved)
    return solved


def bayesian_reference(env: FdiaParallelEnv, agent: str = "attacker") -> Reference:
    """The typed sensor game's exact Bayesian game and its LP equilibrium.

    The game of ``sensor_game_v0(types=..., priors=..., attacker_model=...)`` is a
    :class:`~baselines.game.bayesian.BayesianGame` with one payoff matrix per type.

    The value is the attacker's equilibrium payoff (the defender's return: minus it); the
    policy is ``agent``'s equilibrium strategy (an informed attacker's: one mix per type, read
    from its observation). ``payoff`` is ``L̄`` for an uninformed attacker, else None.
    """
    from baselines.game import MixedStrategyPolicy, TypedMixedStrategyPolicy, bayesian_game_of

    attack = env.attack
    game = _cached_bayesian_game(env, bayesian_game_of)
    sol = game.solution
    name = f"Bayesian equilibrium (LP, {attack.attacker_model} attacker)"
    payoff = game.mean_payoff if game.attacker == "uninformed" else None
    if agent == "defender":
        policy = MixedStrategyPolicy(sol.x, seed=0)
        return Reference(-sol.value, name, "trace", True, payoff, policy, bayes=game)
    if game.attacker == "uninformed":
        policy = MixedStrategyPolicy(sol.y[0], seed=0)
    else:
        policy = TypedMixedStrategyPolicy(sol.y, seed=0)
    return Reference(sol.value, name, "trace", True, payoff, policy, bayes=game)


def detection_reference(env: FdiaParallelEnv, agent: str = "defender") -> Reference | None:
    """OBDD's threshold α (OBDI's when the defender incorporates) under the Bayes-cost criterion.

    The detectors of docs/math.md §3 minimise the Bayes cost built from the fixed costs c1..c4, so
    with ``criterion="bayes_cost"``, the quadratic statistic, one attack step and the defender's
    model equal to the attacker's (the env's defaults) the best fixed threshold is α. The
    attacker's side, and the true-MSE criterion, have no closed-form reference here.
    """
    from baselines.detection import bayes_cost, obdd, obdi, static_problem, tracking_problem
    from fdia_env.detection_game_v0 import FixedAction, _is_static

    det, spec = env.defense, env.spec
    if (
        agent != "defender"
        or det.criterion != "bayes_cost"
        or det.statistic != "quadratic"
        or spec.horizon != 1
        or spec.reward_mode == "shaped"
    ):
        return None
    if not np.allclose(det.assumed_sigma, env.default_sigma):
        return None  # a mis-specified defender: α is no longer the optimum
    power = env.attack.power
    static = _is_static(env.system)
    problem = (
        static_problem(env.scenario, power=power)
        if static
        else tracking_problem(env.scenario, power=power)
    )
    detector = obdd(problem) if det.on_detect == "discard" else obdi(problem)
    policy = FixedAction(det.threshold_to_action(detector.threshold))
    name = f"{detector.name} α (Bayes cost)"
    return Reference(-bayes_cost(detector).value, name, "trace", policy=policy, cost=True)


# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Trainable:
    """One learning agent of one env.

    The Gymnasium id of the agent's single-agent view, :attr:`gym_id`, is the env's entry in
    the table of environments (:data:`fdia_env.registration.ENVS`).

    Attributes:
        env: Registry name (the PettingZoo module name, e.g. ``"sparse_attack_v2"``).
        agent: ``"attacker"`` or ``"defender"``.
        scenarios: Scenario preset → its default env kwargs (the first preset is the default).
        algorithms: stable-baselines3 algorithms that fit the action space (first = default).
        reference: Analytic reference of a built env, ``f(parallel_env)`` or, for games,
            ``f(parallel_env, agent)`` (see :class:`Reference`); None for an env trained
            without one (the stealth envs: their optima are scored by
            ``experiments/results/stealth.py``).
        game: Whether the env is a two-player game (score: exploitability; self-play applies).
        masked: Whether the agent has illegal actions (``env.action_masks()``).
    """

    env: str
    agent: str
    scenarios: Mapping[str, Mapping[str, Any]]
    algorithms: tuple[str, ...]
    reference: Callable[..., Reference | None] | None
    game: bool = False
    masked: bool = False

    @property
    def gym_id(self) -> str:
        """Gymnasium id of the agent's single-agent view (from the table of environments)."""
        return get_env(self.env).views[self.agent]

    @property
    def default_scenario(self) -> str:
        """The first scenario of :attr:`scenarios`."""
        return next(iter(self.scenarios))

    @property
    def default_algorithm(self) -> str:
        """The first algorithm of :attr:`algorithms`."""
        return self.algorithms[0]

    def env_kwargs(self, scenario: str | None = None, **overrides: Any) -> dict[str, Any]:
        """``gym.make`` kwargs: the scenario's defaults updated with ``overrides``.

        Raises:
            ValueError: For a scenario this env is not set up for (listing the valid ones).
        """
        scenario = self.default_scenario if scenario is None else scenario
        if scenario not in self.scenarios:
            raise ValueError(
                f"unknown scenario {scenario!r} for {self.env} ({self.agent}); "
                f"valid scenarios: {', '.join(self.scenarios)}"
            )
        table = SCENARIO_DEFAULTS.get((self.env, scenario))
        preset = {} if table is None else table.env_kwargs
        if "action" in overrides and overrides["action"] != preset.get("action"):
            preset = {}  # the table's options go with its action format (e.g. the order)
        return {"scenario": scenario, **self.scenarios[scenario], **preset, **overrides}

    def algorithm(self, name: str | None) -> str:
        """Canonical algorithm name (case and ``_``/``-`` insensitive); None gives the default.

        Raises:
            ValueError: For an algorithm unknown or not applicable here (listing the valid ones).
        """
        if name is None:
            return self.default_algorithm
        key = name.replace("_", "").replace("-", "").lower()
        for algo in self.algorithms:
            if algo.lower() == key:
                return algo
        why = "unknown algorithm" if key not in {a.lower() for a in ALGORITHMS} else "algorithm"
        raise ValueError(
            f"{why} {name!r} does not apply to {self.env} ({self.agent}); "
            f"valid algorithms: {', '.join(self.algorithms)}"
        )

    def make(self, scenario: str | None = None, **overrides: Any) -> gym.Env:
        """``gymnasium.make`` the view with :meth:`env_kwargs`."""
        return gym.make(self.gym_id, **self.env_kwargs(scenario, **overrides))

    def make_resolved(self, env_kwargs: dict[str, Any], **extra: Any) -> gym.Env:
        """``gymnasium.make`` the view with exactly ``env_kwargs`` (and ``extra``, an opponent).

        For options already resolved (:meth:`env_kwargs`'s, or a resumed run's saved ones):
        the scenario's defaults are not applied again, so a run saved under former defaults
        gets its own env, not today's.
        """
        return gym.make(self.gym_id, **env_kwargs, **extra)

    def view(self, opponent: Any = None, **env_kwargs: Any) -> gym.Env:
        """The view built directly, without ``gymnasium.make``.

        For an ``opponent`` that cannot be deep-copied into the env spec (an SB3 model):
        ``gymnasium.make`` copies its kwargs and warns when it cannot.
        """
        from fdia_env.envs.single_agent import make_single_agent

        module = get_env(self.env).module
        return make_single_agent(module, agent=self.agent, opponent=opponent, **env_kwargs)

    def reference_of(self, env: gym.Env) -> Reference | None:
        """The analytic reference of a built view (None where none applies)."""
        if self.reference is None:
            return None
        if self.game:
            return self.reference(parallel_of(env), self.agent)
        return self.reference(parallel_of(env))


REGISTRY: dict[tuple[str, str], Trainable] = {}


def register(entry: Trainable) -> Trainable:
    """Add ``entry`` under ``(entry.env, entry.agent)`` (replacing one already there)."""
    if entry.agent not in AGENTS:
        raise ValueError(f"agent must be one of {list(AGENTS)}, got {entry.agent!r}")
    unknown = [a for a in entry.algorithms if a not in ALGORITHMS]
    if unknown or not entry.algorithms:
        raise ValueError(f"algorithms must be a non-empty subset of {ALGORITHMS}, got {unknown}")
    if not entry.scenarios:
        raise ValueError(f"{entry.env} needs at least one scenario")
    views = get_env(entry.env).views  # an env not in the table fails here, naming the envs
    if entry.agent not in views:
        raise ValueError(
            f"{entry.env} has no single-agent view for the {entry.agent}; its views: "
            f"{', '.join(views) or 'none'}"
        )
    REGISTRY[entry.env, entry.agent] = entry
    return entry


def names(agent: str = "attacker") -> list[str]:
    """Registered env names that have a learning ``agent``."""
    return [env for env, a in REGISTRY if a == agent]


def game_names() -> list[str]:
    """Registered two-player games (both sides registered): the self-play envs."""
    return [
        env
        for (env, agent), e in REGISTRY.items()
        if agent == "attacker" and e.game and (env, "defender") in REGISTRY
    ]


def get(env: str, agent: str = "attacker") -> Trainable:
    """The entry of ``env`` (registry name or Gymnasium id) for ``agent``.

    Raises:
        ValueError: For an unknown agent, or an env that has no such learning agent (listing the
            envs that have one).
    """
    if agent not in AGENTS:
        raise ValueError(f"agent must be one of {list(AGENTS)}, got {agent!r}")
    for entry in REGISTRY.values():
        if entry.gym_id == env:
            if entry.agent != agent:
                raise ValueError(f"{env} is the {entry.agent}'s view, not the {agent}'s")
            return entry
    if (env, agent) in REGISTRY:
        return REGISTRY[env, agent]
    known = {e for e, _ in REGISTRY}
    what = f"{env!r} has no learning {agent}" if env in known else f"unknown env {env!r}"
    raise ValueError(f"{what}; envs with a learning {agent}: {', '.join(names(agent))}")


def by_gym_id(gym_id: str) -> Trainable | None:
    """The entry whose view is ``gym_id``, or None."""
    return next((e for e in REGISTRY.values() if e.gym_id == gym_id), None)


# the grid presets keep their own budget and horizon (c = 6; N = 6, 4, 3, 3) and take the
# sequential format from agents.config.SCENARIO_DEFAULTS
_SPARSE_SCENARIOS = {
    "ch4-position": {"budget": 5, "horizon": 6},
    "ch4-pv-case1": {"budget": 5, "horizon": 6, "objective": "logdet"},
    "ch4-pv-case2": {"budget": 5, "horizon": 6, "objective": "logdet"},
    "ch4-pv-case3": {"budget": 5, "horizon": 6, "objective": "logdet"},
    "ch4-random": {"budget": 10, "horizon": 6},
    **{name: {} for name in GRID_PRESETS},
    "dc-ieee14-50": {},  # c = 5, N = 6 of the preset; the trace (the env's default objective)
    "grid-ieee14-rtu": {"objective": "logdet"},  # c = 6, N = 6 of the preset
}
_COVARIANCE_SCENARIOS = {
    "ch2-position": {"power": 3000.0},
    "ch2-pv-1": {"power": 3000.0},
    "ch2-pv-2": {"power": 3000.0},
}
# allocation is left to the env's default ("independent"): a typed game (types=...) takes none
_GAME_SCENARIOS = {"ch5-game": {"power": 100.0}, "game-m10": {"power": 100.0}, "grid-ieee14": {}}

# the newest version first (train.py's default env); the older ones stay by name, so their
# run folders resume and their results can be retrained (each version's Version History says
# what changed: the defaults of the action format and the decision order, nothing else)
for _sparse in SPARSE_ENVS:
    register(
        Trainable(
            _sparse,
            "attacker",
            _SPARSE_SCENARIOS,
            MASKED_ALGORITHMS,
            sparse_reference,
            masked=True,
        )
    )
register(
    Trainable(
        "covariance_attack_v0",
        "attacker",
        _COVARIANCE_SCENARIOS,
        BOX_ALGORITHMS,
        covariance_reference,
    )
)
for _agent in ("attacker", "defender"):
    register(
        Trainable(
            "sensor_game_v0",
            _agent,
            _GAME_SCENARIOS,
            (*DISCRETE_ALGORITHMS, "MaskablePPO"),  # MaskablePPO: action="sequential" only
            game_reference,
            game=True,
        )
    )

_DETECTION_SCENARIOS = {
    "ch3-static": {"power": 240.0, "criterion": "bayes_cost"},
    "ch3-tracking": {"power": 7.5, "criterion": "bayes_cost"},
}
register(
    Trainable(
        "detection_game_v0",
        "defender",
        _DETECTION_SCENARIOS,
        BOX_ALGORITHMS,
        detection_reference,
    )
)

# the stealthy attacks: trained without a reference here; the static env's free injection
# (a Box: every algorithm, torch-ppo included; --env-kwargs action '"box_shift"' for PPO/A2C)
register(
    Trainable(
        "stealth_attack_v0",
        "attacker",
        {"grid-ieee14": {"action": "free"}, "grid-ieee118": {"action": "free"}},
        BOX_ALGORITHMS,
        None,
    )
)
register(Trainable("stealth_dynamic_v0", "attacker", {"ch4-position": {}}, BOX_ALGORITHMS, None))
