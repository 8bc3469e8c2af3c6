"""A named benchmark task: how to build its env, its stored references, its normalised score.

A :class:`Task` is pure data: the Gymnasium id and kwargs of the env a policy plays, the
PettingZoo module, the number of episodes a score averages over, and the reference values the
project's solvers computed for it (:class:`References`: random play, the polynomial heuristics,
the certified optimum or the best known value with its certified bound, the game value for
games, the solver versions and the date). :meth:`Task.normalise` maps a raw number to the
normalised score of docs/benchmark.md, "Normalised score":

``score = (raw − random) / (optimum − random)``

so random play scores 0 and the certified optimum (the game value in a game) scores 1. In a
single-player task ``raw`` is the mean episode return. In a game task (``metric ==
"worst-case return"``) it is the return the policy guarantees against a best-responding
opponent, ``value − exploitability`` (:meth:`Task.normalise_exploitability`), so the score is
``1 − exploitability / exploitability of uniform random play``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

# Gymnasium's notice that a newer version of an env id exists (logger.deprecation).
OUT_OF_DATE = r".*The environment \S+ is out of date\. You should consider upgrading"


def make_pinned(env_id: str, entry_point: str | None, kwargs: Mapping[str, Any]) -> Any:
    """``gymnasium.make`` a task's env: its id, pinned to a version, with ``kwargs``.

    A task pins the version its references were computed on (the sparse tasks:
    ``fdia_env/SparseAttack-v0``, whose newer versions change default options only), so
    Gymnasium's "is out of date" notice is expected here and says nothing to the user: that
    one warning is filtered while the env is built; every other warning passes.

    Args:
        env_id: The task's Gymnasium id.
        entry_point: ``"module:Class"`` for an id built without the registry, else None.
        kwargs: The env's keyword arguments.
    """
    import warnings

    import gymnasium

    target: Any = env_id
    if entry_point is not None:
        target = gymnasium.envs.registration.EnvSpec(env_id, entry_point=entry_point)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", OUT_OF_DATE, DeprecationWarning)
        return gymnasium.make(target, **kwargs)


FAMILIES = (
    "sparse",
    "covariance",
    "sensor-game",
    "detection-game",
    "incomplete-information",
    "system-family",
    "stealth",
)
PLAYERS = ("attacker", "defender")
DIFFICULTIES = ("easy", "medium", "hard")
METRICS = ("return", "worst-case return")
OBJECTIVES = ("trace", "logdet", "cost", "value")

# grading thresholds (docs/benchmark.md, "Tasks"): a task is hard when random play reaches at
# most RANDOM_HARD of the optimum (ratio), the best polynomial heuristic at most HEURISTIC_HARD
# normalised, and the optimum is certified (proved, or a certified gap of at most GAP_HARD)
RANDOM_HARD = 0.5
HEURISTIC_HARD = 0.9
HEURISTIC_MEDIUM = 0.99
GAP_HARD = 0.05


@dataclass(frozen=True)
class RandomReference:
    """Uniformly random play: mean raw number, 95 % CI half-width, how it was measured.

    Attributes:
        mean: Mean episode return (a game: the worst-case return of the uniform mix, exact).
        ci95: Half-width of the 95 % Student-t interval of ``mean`` (0 where it is exact).
        episodes: Episodes played (0 where the number is computed exactly).
        seed: Seed of the first episode (episode ``i`` is reset with ``seed + i``).
    """

    mean: float
    ci95: float
    episodes: int
    seed: int


@dataclass(frozen=True)
class Optimum:
    """The certified reference: the optimum, or the best known value with a certified bound.

    Attributes:
        value: Its raw number (a game: the game value, in the player's return).
        name: The solver (``"EXS"``, ``"B&B (certified optimum)"``, ``"game value (LP)"``...).
        certified: True when ``value`` is proved optimal.
        bound: A certified bound on the optimum (the value itself when certified).
        gap: ``1 − ratio(value, bound)``: how far the best known value may be from the optimum,
            as a fraction of the ratio score (0 when certified).
    """

    value: float
    name: str
    certified: bool
    bound: float
    gap: float


@dataclass(frozen=True)
class References:
    """The stored reference values of a task (``fdia_env/tasks/references.json``).

    Attributes:
        objective: How raw numbers compare (:meth:`ratio`): ``"trace"`` (positive returns,
            ratio ``raw / optimum``), ``"logdet"`` (determinant ratio ``exp(raw − optimum)``),
            ``"cost"`` (negative returns, ratio ``optimum / raw``) or ``"value"`` (game
            payoffs, ratio ``raw / optimum``).
        metric: ``"return"`` (mean episode return) or ``"worst-case return"`` (games).
        random: Uniformly random play.
        heuristics: Polynomial-time heuristic → its raw number.
        optimum: The certified reference.
        game_value: The game's value in the player's return (games), else None.
        solvers: Package → version used to compute the references.
        date: ISO date of the computation.
    """

    objective: str
    metric: str
    random: RandomReference
    heuristics: Mapping[str, float]
    optimum: Optimum
    game_value: float | None
    solvers: Mapping[str, str]
    date: str

    def __post_init__(self) -> None:
        if self.objective not in OBJECTIVES:
            raise ValueError(f"objective must be one of {list(OBJECTIVES)}, got {self.objective!r}")
        if self.metric not in METRICS:
            raise ValueError(f"metric must be one of {list(METRICS)}, got {self.metric!r}")
        if not self.optimum.value != self.random.mean:
            raise ValueError("optimum equals random play: the normalised score is undefined")
        if self.objective != "logdet" and self.optimum.value == 0.0:
            raise ValueError("optimum is 0: the ratio of a return to it is undefined")
        if self.objective == "cost" and self.random.mean == 0.0:
            raise ValueError("random play's cost is 0: its ratio to the optimum is undefined")
        object.__setattr__(self, "heuristics", MappingProxyType(dict(self.heuristics)))
        object.__setattr__(self, "solvers", MappingProxyType(dict(self.solvers)))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> References:
        """Build from the JSON form (:meth:`to_dict`)."""
        return cls(
            objective=data["objective"],
            metric=data["metric"],
            random=RandomReference(**data["random"]),
            heuristics={k: float(v) for k, v in data["heuristics"].items()},
            optimum=Optimum(**data["optimum"]),
            game_value=data.get("game_value"),
            solvers=dict(data["solvers"]),
            date=data["date"],
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON form."""
        return {
            "objective": self.objective,
            "metric": self.metric,
            "random": vars(self.random).copy(),
            "heuristics": dict(self.heuristics),
            "optimum": vars(self.optimum).copy(),
            "game_value": self.game_value,
            "solvers": dict(self.solvers),
            "date": self.date,
        }

    def normalise(self, raw: float) -> float:
        """``(raw − random) / (optimum − random)``: 0 = random play, 1 = the optimum."""
        low, high = self.random.mean, self.optimum.value
        return (float(raw) - low) / (high - low)

    def ratio(self, raw: float, to: float | None = None) -> float:
        """``raw`` as a fraction of the optimum (or of ``to``), in the objective's convention."""
        ref = self.optimum.value if to is None else float(to)
        if self.objective == "logdet":
            return math.exp(float(raw) - ref)
        if self.objective == "cost":
            return ref / float(raw)
        return float(raw) / ref

    @property
    def best_heuristic(self) -> tuple[str, float] | None:
        """``(name, raw)`` of the heuristic with the highest raw number, None without one."""
        if not self.heuristics:
            return None
        return max(self.heuristics.items(), key=lambda kv: kv[1])

    @property
    def random_ratio(self) -> float:
        """Random play as a fraction of the optimum (:meth:`ratio`)."""
        return self.ratio(self.random.mean)

    @property
    def heuristic_score(self) -> float | None:
        """The best heuristic's normalised score (None without heuristics)."""
        best = self.best_heuristic
        return None if best is None else self.normalise(best[1])

    @property
    def is_certified(self) -> bool:
        """The optimum is proved, or its certified gap is at most :data:`GAP_HARD`."""
        return self.optimum.certified or self.optimum.gap <= GAP_HARD

    def grade(self) -> str:
        """``"hard"``, ``"medium"`` or ``"easy"``, from the stored numbers.

        Hard: random play reaches at most 50 % of the optimum (:attr:`random_ratio`), the best
        heuristic at most 0.9 normalised, and the optimum is certified (or its gap ≤ 5 %).
        Medium: random at most 50 % of the optimum, or the best heuristic below 0.99
        normalised. Easy: the rest (a heuristic solves it and random play is close).
        """
        heuristic = self.heuristic_score
        random_far = self.random_ratio <= RANDOM_HARD
        if (
            random_far
            and heuristic is not None
            and heuristic <= HEURISTIC_HARD
            and self.is_certified
        ):
            return "hard"
        if random_far or (heuristic is not None and heuristic < HEURISTIC_MEDIUM):
            return "medium"
        return "easy"


@dataclass(frozen=True)
class Task:
    """One named, versioned benchmark task.

    Attributes:
        name: ``"family/instance-vN"`` (``"sparse/ch4-position-v0"``).
        family: One of :data:`FAMILIES`.
        player: ``"attacker"`` or ``"defender"``: whose return is scored.
        difficulty: ``"easy"``, ``"medium"`` or ``"hard"``, graded from the stored references
            (:meth:`References.grade`).
        env_id: Gymnasium id of the env the player acts in.
        env_kwargs: Keyword arguments for ``gymnasium.make(env_id, ...)`` (a view's ``agent``
            is in the id; the sequential format, budgets, horizons... are here).
        module: Import path of the PettingZoo module of the env (None for an env without one).
        episodes: Episodes a score averages over (episode ``i`` is reset with ``seed + i``).
        description: One line on what the task is.
        references: The stored reference values.
        entry_point: ``"module:Class"`` of an env not registered with Gymnasium (the system
            family); None for a registered ``env_id``.
    """

    name: str
    family: str
    player: str
    difficulty: str
    env_id: str
    env_kwargs: Mapping[str, Any]
    module: str | None
    episodes: int
    description: str
    references: References = field(repr=False)
    entry_point: str | None = None

    def __post_init__(self) -> None:
        if self.family not in FAMILIES:
            raise ValueError(f"family must be one of {list(FAMILIES)}, got {self.family!r}")
        if self.player not in PLAYERS:
            raise ValueError(f"player must be one of {list(PLAYERS)}, got {self.player!r}")
        if self.difficulty not in DIFFICULTIES:
            raise ValueError(
                f"difficulty must be one of {list(DIFFICULTIES)}, got {self.difficulty!r}"
            )
        if not isinstance(self.episodes, int) or self.episodes < 1:
            raise ValueError(f"episodes must be a positive integer, got {self.episodes!r}")
        object.__setattr__(self, "env_kwargs", MappingProxyType(dict(self.env_kwargs)))

    @property
    def is_game(self) -> bool:
        """Whether the score is exploitability-based (the raw number a worst-case return)."""
        return self.references.metric == "worst-case return"

    def make_env(self, **overrides: Any) -> Any:
        """``gymnasium.make`` the task's env with its kwargs updated by ``overrides``.

        An override changes the task: a score on such an env is not the task's score.
        """
        return make_pinned(self.env_id, self.entry_point, {**self.env_kwargs, **overrides})

    def normalise(self, raw: float) -> float:
        """The normalised score of ``raw``: 0 = random play, 1 = the certified optimum.

        ``raw`` is the mean episode return, or in a game the policy's worst-case return
        (``value − exploitability``; see :meth:`normalise_exploitability`).

        Raises:
            TypeError: For a ``raw`` that is not a real number.
            ValueError: For a NaN or infinite ``raw``.
        """
        if isinstance(raw, (bool, str, bytes)) or not hasattr(raw, "__float__"):
            raise TypeError(f"raw must be a real number, got {type(raw).__name__}")
        value = float(raw)
        if not math.isfinite(value):
            raise ValueError(f"raw must be finite, got {raw!r}")
        return self.references.normalise(value)

    def normalise_exploitability(self, exploitability: float) -> float:
        """A game task's score from an exploitability: ``normalise(value − exploitability)``.

        Equals ``1 − exploitability / exploitability of uniform random play``.

        Raises:
            ValueError: On a task that is not a game, or for a negative exploitability.
        """
        if not self.is_game:
            raise ValueError(f"task {self.name!r} is not a game: score its mean return")
        expl = float(exploitability)
        if not expl >= -1e-9:
            raise ValueError(f"exploitability must be >= 0, got {exploitability!r}")
        return self.normalise(self.references.optimum.value - expl)
