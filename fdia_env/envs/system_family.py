"""One sparse attacker for many systems: ``sparse_attack_v0`` over a distribution of systems.

:class:`SystemFamilyEnv` is a Gymnasium env that, at every reset, draws a new system from a
family (:class:`TrackingFamily`: random tracking systems as in the ``ch4-random`` preset,
docs/math.md §6; or :class:`fdia_env.envs.grid_family.GridFamily`: the IEEE 14-bus DC state
estimation with random loads and meter noise, 34 meters, ``action="sequential"`` only) and
plays one episode of ``sparse_attack_v0`` (perfect detection, expected dynamics, terminal
reward) on it. Its observation is the sparse env's observation followed by a
fixed-size *description* of the current system, so one policy can attack every system of the
family; the action mask is kept (MaskablePPO).

## Which system is drawn

Systems are indexed by an integer *system seed* ``k``: ``family.system(k)`` is
``family.draw(numpy.random.default_rng(k))``. At each reset the env picks ``k`` uniformly from
``system_seeds`` (a ``range``) with its own generator, which ``reset(seed=...)`` seeds, so a
seeded reset sequence is reproducible. ``reset(options={"system_seed": k})`` pins the system
(any ``k >= 0``, also outside ``system_seeds``: that is how held-out systems are scored).
``info["system_seed"]`` says which system the episode runs. What an episode needs of a system
(the system itself, its sparse env, its steady state, description, slot order and reward scale)
is prepared the first time the system is drawn and kept (up to :data:`CACHED_SYSTEMS` systems,
the least recently drawn dropped first), so a reset on a family of a few systems costs a reset
of the sparse env; a kept system replays exactly as a freshly prepared one.

## Observation

``Box(float32)`` of size ``d_sparse (+ max_sensors) + d_description``:

- ``[0 : d_sparse]``: the sparse env's observation (steps left / N, log variance growth,
  covariance correlations, budget left / c; see :mod:`fdia_env.sparse_attack_v0`);
  ``d_sparse = 2 + n + n(n−1)/2`` (5 for the tracking systems);
- ``action="sequential"`` only: ``max_sensors`` 0/1 entries, the sensors picked so far for the
  current window step;
- then (unless ``describe=False``) the description (:func:`describe_system`), with
  ``P̄ = F P F' + Q`` the steady-state predicted covariance, ``P`` the steady-state filtered
  covariance (all sensors) and ``s = tr P̄`` the scale:

| entries | feature | range |
|---|---|---|
| 1 | log10 s | [-10, 10] (clipped) |
| n² | F, row-major | [-10, 10] (clipped) |
| n(n+1)/2 | Q / s, upper triangle row-major | [-1, 1] |
| n(n+1)/2 | P / s, upper triangle row-major | [-1, 1] |
| max_sensors | present: 1 for a sensor, 0 for a padding slot (j >= M) | {0, 1} |
| max_sensors × n | H_j / ‖H_j‖ (direction of the sensor's row) | [-1, 1] |
| max_sensors | log10(s ‖H_j‖² / R_j) (signal-to-noise ratio) | [-10, 10] (clipped) |
| max_sensors | attack effect e_j (below) | [0, 1] (trace) |

The per-sensor entries are stored slot by slot: slot j holds (present, H_j / ‖H_j‖, log SNR,
e_j), ``n + 3`` numbers, zeros for a padding slot. Slot j is sensor j, or, with
``sort_sensors=True``, the sensor with the j-th largest attack effect (``info["slot_sensors"]``
maps slots to sensors; actions then name slots).

The attack effect of sensor j is what dropping it alone, for one step from steady state, adds
to the objective: ``e_j = (tr P_{−j} − tr P) / s`` for the trace (in [0, 1]) and
``log det P_{−j} − log det P`` for log det (clipped to [0, 30]), with
``P_{−j} = (P̄⁻¹ + Σ_{i ≠ j} H_i' R_i⁻¹ H_i)⁻¹``. Sensors must be scalar (one measurement row).
For ``n = 2`` and ``max_sensors = 10`` the description has 61 entries.

## Action

``action="bitmask"`` (default): ``Discrete(2**max_sensors)``, a bitmask of attacked sensors per
window step as in ``sparse_attack_v0``. Bits of absent sensor slots (``j >= M``) are ignored; a
subset above the budget left is trimmed to its lowest-numbered sensors (the sparse env's
``"trim"`` rule). ``action_masks()`` and ``info["action_mask"]`` mark the subsets of present
sensors within the budget left.

``action="sequential"``: ``Discrete(max_sensors + 1)``, the same attack built one sensor per
decision: action ``j + 1`` adds sensor j to the current window step's subset (reward 0, the
window does not advance), action 0 commits the subset and plays the step. The mask allows 0
always (on the last window step only once no pick is legal, with ``spend_budget``: attacking
more never lowers Φ, so no optimum is excluded) and ``j + 1`` for a present sensor not picked
yet this step while the picks leave budget; an illegal pick or commit changes nothing. An
episode has N commits and at most c picks. Every attack set of the bitmask format is reachable
(with ``spend_budget``, those that spend the budget left, or attack every sensor, on the last
step: every optimum among them); the policy's
output has M + 1 entries instead of 2^M, which learns far faster (see
``docs/results/general.md``).

## Reward

The sparse env's terminal reward Φ(P[K+N|K+N]) (``info["phi"]``), divided by ``s`` for the
trace when ``normalize_reward`` (for log det: minus ``log det P̄``), or by a per-system
reference value when ``reward_reference`` is given, so rewards are comparable
across systems; ``info["phi"]`` is always the raw objective.

>>> env = SystemFamilyEnv(TrackingFamily(), system_seeds=range(0, 1000))
>>> obs, info = env.reset(seed=0)
>>> obs.shape, int(env.action_space.n), info["system_seed"] in range(0, 1000)
((66,), 1024, True)
>>> env = SystemFamilyEnv(TrackingFamily(), action="sequential", max_sensors=12)
>>> env.reset(seed=0)[0].shape, int(env.action_space.n)
((88,), 13)
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from fdia_env._validation import check_choice, check_int
from fdia_env.actions import check_action
from fdia_env.attacks.sparse import MAX_SENSORS, SparseAttack
from fdia_env.defenses import PerfectDetection
from fdia_env.envs.factory import episode_spec
from fdia_env.envs.family import NumberedFamily, check_range
from fdia_env.envs.grid_family import GridFamily
from fdia_env.envs.parallel import FdiaParallelEnv
from fdia_env.envs.single_agent import SingleAgentEnv
from fdia_env.kalman import information_update, objective, steady_state
from fdia_env.systems import LinearSystem, tracking_system

OBJECTIVES = ("trace", "logdet")
ACTIONS = ("bitmask", "sequential")
CLIP = 10.0
LOGDET_EFFECT_MAX = 30.0
SIGMA_W_FLOOR = 1e-6  # as ch4-random: U(0, 1) can return exactly 0; a sensor needs R > 0
MAX_SEQUENTIAL_SENSORS = 128
"""Largest ``max_sensors`` of ``action="sequential"`` (the bitmask action stops at 16)."""
CACHED_SYSTEMS = 4096
"""Systems whose precomputed episode setup a :class:`SystemFamilyEnv` keeps (least recently
drawn dropped first)."""


@dataclass(frozen=True)
class _Prepared:
    """What a reset needs of one system, computed once per system seed."""

    system: LinearSystem
    inner: SingleAgentEnv
    order: np.ndarray
    description: np.ndarray
    scale: float


@dataclass(frozen=True)
class TrackingFamily(NumberedFamily):
    """Random tracking systems as in the ``ch4-random`` preset (docs/math.md §6).

    A draw: ``num_sensors`` position sensors with ``σ_w ~ U(sigma_w)`` (floored at 1e-6), then
    the process noise ``σ_v`` log-uniform on ``sigma_v``; the model is
    :func:`fdia_env.systems.tracking_system` (``x = [position, velocity]``, T = 1). With
    ``sigma_v=(0.1, 0.1)`` and the defaults otherwise, ``system(k)`` is the ``ch4-random``
    preset's system for ``seed=k``.

    Attributes:
        num_sensors: Sensors per system M (1..16).
        sigma_v: (low, high) range of the process noise σ_v, log-uniform, low > 0.
        sigma_w: (low, high) range of the sensor noise σ_w, uniform, low >= 0.
        budget: Sparsity budget c of the attack, 0..M·N.
        horizon: Attack window N >= 1.
    """

    num_sensors: int = 10
    sigma_v: tuple[float, float] = (0.1, 1.0)
    sigma_w: tuple[float, float] = (0.0, 1.0)
    budget: int = 10
    horizon: int = 6

    def __post_init__(self) -> None:
        check_int("num_sensors", self.num_sensors, minimum=1, maximum=MAX_SENSORS)
        object.__setattr__(self, "sigma_v", check_range("sigma_v", self.sigma_v))
        object.__setattr__(self, "sigma_w", check_range("sigma_w", self.sigma_w, closed=True))
        check_int("horizon", self.horizon, minimum=1, maximum=10_000)
        check_int("budget", self.budget, minimum=0, maximum=self.num_sensors * self.horizon)

    @property
    def state_size(self) -> int:
        """State dimension n of every system (2: position and velocity)."""
        return 2

    def draw(self, rng: np.random.Generator) -> LinearSystem:
        """One system, drawn with ``rng`` (σ_w first, then σ_v)."""
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy Generator, got {type(rng).__name__}")
        sigma_w = rng.uniform(*self.sigma_w, size=self.num_sensors)
        sigma_w = np.maximum(sigma_w, SIGMA_W_FLOOR)
        lo, hi = self.sigma_v
        sigma_v = float(np.exp(rng.uniform(math.log(lo), math.log(hi))))
        return tracking_system(sigma_v, list(sigma_w), name="tracking-family")


def _upper(a: np.ndarray) -> np.ndarray:
    return a[np.triu_indices(a.shape[0])]


def describe_system(
    system: LinearSystem,
    max_sensors: int,
    objective_name: str = "trace",
    order: np.ndarray | None = None,
    *,
    steady: tuple[np.ndarray, np.ndarray] | None = None,
    effect: np.ndarray | None = None,
) -> np.ndarray:
    """The fixed-size description of ``system`` (see the module docstring), float64.

    Args:
        system: A system with scalar sensors and at most ``max_sensors`` of them.
        max_sensors: Number of sensor slots (padding with zeros).
        objective_name: ``"trace"`` or ``"logdet"`` (the attack effect terms' objective).
        order: Slot j describes sensor ``order[j]`` (a permutation of ``range(M)``; default
            the identity).
        steady: ``(P̄, P)``, the system's steady-state predicted and filtered covariances,
            where the caller has them (default: solved here).
        effect: The sensors' attack effects ``e_j`` , where the caller
            has them (default: computed here, as in the module docstring).

    Raises:
        ValueError: For a system with a non-scalar sensor or more than ``max_sensors``.
    """
    if not isinstance(system, LinearSystem):
        raise ValueError(f"system must be a LinearSystem, got {type(system).__name__}")
    check_int("max_sensors", max_sensors, minimum=1, maximum=MAX_SEQUENTIAL_SENSORS)
    check_choice("objective", objective_name, OBJECTIVES)
    if system.M > max_sensors:
        raise ValueError(f"system has {system.M} sensors, above max_sensors = {max_sensors}")
    if any(s.dim != 1 for s in system.sensors):
        raise ValueError("system must have scalar sensors (one measurement row each)")
    n = system.n
    P_pred, P = steady_state(system)[:2] if steady is None else steady
    s = float(np.trace(P_pred))
    head = [
        [np.clip(math.log10(s), -CLIP, CLIP)],
        np.clip(system.F.reshape(-1), -CLIP, CLIP),
        _upper(system.Q) / s,
        _upper(P) / s,
    ]
    slots = np.zeros((max_sensors, n + 3))
    if effect is None:
        effect = _attack_effect(system, P_pred, P, objective_name)
    order = np.arange(system.M) if order is None else np.asarray(order)
    if sorted(order.tolist()) != list(range(system.M)):
        raise ValueError(f"order must be a permutation of range({system.M}), got {order!r}")
    for j, i in enumerate(order.tolist()):
        sensor = system.sensors[i]
        h = sensor.H.reshape(-1)
        norm = float(np.linalg.norm(h))
        snr = s * norm**2 / float(sensor.R[0, 0])
        slots[j, 0] = 1.0
        slots[j, 1 : 1 + n] = h / norm if norm > 0 else 0.0
        slots[j, 1 + n] = np.clip(math.log10(snr), -CLIP, CLIP) if snr > 0 else -CLIP
        slots[j, 2 + n] = effect[i]
    return np.concatenate([*(np.asarray(h, float) for h in head), slots.reshape(-1)])


def _attack_effect(
    system: LinearSystem, P_pred: np.ndarray, P: np.ndarray, objective_name: str
) -> np.ndarray:
    """Every sensor's attack effect ``e_j`` from the steady state ``(P̄, P)`` (module docstring)."""
    drop_one = ~np.eye(system.M, dtype=bool)  # row j: every sensor but j
    P_minus = information_update(P_pred, system.J, drop_one)  # (M, n, n)
    if objective_name == "trace":
        return (np.trace(P_minus, axis1=-2, axis2=-1) - np.trace(P)) / float(np.trace(P_pred))
    effect = objective(P_minus, "logdet") - objective(P, "logdet")
    return np.clip(effect, 0.0, LOGDET_EFFECT_MAX)


def effect_order(system: LinearSystem, objective_name: str = "trace") -> np.ndarray:
    """Sensors by decreasing attack effect ``e_j`` (ties: lower index first)."""
    effect = describe_system(system, system.M, objective_name)[-system.M * (system.n + 3) :]
    return np.argsort(-effect.reshape(system.M, -1)[:, -1], kind="stable")


def description_size(state_size: int, max_sensors: int) -> int:
    """Length of the description: ``1 + n² + n(n+1) + max_sensors (n + 3)``."""
    n = state_size
    return 1 + n * n + n * (n + 1) + max_sensors * (n + 3)


def _description_bounds(n: int, max_sensors: int, objective_name: str) -> tuple[np.ndarray, ...]:
    tri = n * (n + 1) // 2
    effect_hi = 1.0 if objective_name == "trace" else LOGDET_EFFECT_MAX
    slot_lo = [0.0, *([-1.0] * n), -CLIP, 0.0]
    slot_hi = [1.0, *([1.0] * n), CLIP, effect_hi]
    lo = [-CLIP, *([-CLIP] * n * n), *([-1.0] * 2 * tri), *(slot_lo * max_sensors)]
    hi = [CLIP, *([CLIP] * n * n), *([1.0] * 2 * tri), *(slot_hi * max_sensors)]
    return np.array(lo), np.array(hi)


class SystemFamilyEnv(gym.Env):
    """``sparse_attack_v0`` on a new system of ``family`` at every reset (module docstring).

    Args:
        family: The system distribution (a :class:`TrackingFamily` or a
            :class:`~fdia_env.envs.grid_family.GridFamily`).
        system_seeds: The system seeds drawn from at reset (a non-empty ``range`` of integers
            >= 0); keep training and held-out ranges disjoint.
        max_sensors: Sensor slots of the description and bits of the action (default the
            family's ``num_sensors``; at most 16 with ``action="bitmask"``, at most
            :data:`MAX_SEQUENTIAL_SENSORS` with ``"sequential"``).
        objective: Φ, ``"trace"`` or ``"logdet"``.
        normalize_reward: Divide the terminal reward by ``s = tr P̄`` (trace) or subtract
            ``log det P̄`` (log det).
        reward_reference: ``None``, or a callable ``(system, budget, horizon) -> float`` (a
            positive number, computed once per system and kept with it, e.g. a heuristic's
            value of the system's sparse problem): the terminal reward is then divided by it
            (trace only; replaces ``normalize_reward``'s scale). The env itself calls no solver.
        describe: Append the description; ``False`` gives the sparse env's observation alone
            (the ablation "no description").
        action: ``"bitmask"`` (one subset per window step, ``Discrete(2**max_sensors)``) or
            ``"sequential"`` (one sensor per decision, ``Discrete(max_sensors + 1)``; see the
            module docstring).
        sort_sensors: Order the sensor slots by decreasing attack effect ``e_j`` (slot j is
            sensor ``info["slot_sensors"][j]``; actions name slots), so one action index means
            "the j-th most effective sensor" on every system. Default: slot j is sensor j.
        spend_budget: Sequential only: on the last window step, commit is masked while a pick
            is still legal (attacking more never lowers Φ under perfect detection, so no
            optimum is excluded; it removes a costly mistake from exploration).
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(
        self,
        family: TrackingFamily | GridFamily,
        system_seeds: range = range(0, 1_000_000),
        max_sensors: int | None = None,
        objective: str = "trace",
        normalize_reward: bool = True,
        describe: bool = True,
        action: str = "bitmask",
        reward_reference: Callable[[LinearSystem, int, int], float] | None = None,
        spend_budget: bool = True,
        sort_sensors: bool = False,
    ) -> None:
        if not isinstance(family, (TrackingFamily, GridFamily)):
            raise ValueError(
                f"family must be a TrackingFamily or a GridFamily, got {type(family).__name__}"
            )
        if not isinstance(system_seeds, range) or len(system_seeds) == 0:
            raise ValueError(
                f"system_seeds must be a non-empty range of integers >= 0, got {system_seeds!r}"
            )
        if min(system_seeds[0], system_seeds[-1]) < 0:
            raise ValueError(f"system_seeds must hold integers >= 0, got {system_seeds!r}")
        if max_sensors is None:
            max_sensors = family.num_sensors
        check_choice("action", action, ACTIONS)
        cap = MAX_SEQUENTIAL_SENSORS if action == "sequential" else MAX_SENSORS
        check_int("max_sensors", max_sensors, minimum=family.num_sensors, maximum=cap)
        check_choice("objective", objective, OBJECTIVES)
        flags = (
            ("normalize_reward", normalize_reward),
            ("describe", describe),
            ("spend_budget", spend_budget),
            ("sort_sensors", sort_sensors),
        )
        for name, flag in flags:
            if not isinstance(flag, bool):
                raise ValueError(f"{name} must be True or False, got {flag!r}")
        if reward_reference is not None:
            if not callable(reward_reference):
                raise ValueError(
                    "reward_reference must be None or a callable (system, budget, horizon) -> "
                    f"float, got {type(reward_reference).__name__}"
                )
            if objective != "trace":
                raise ValueError(
                    f"reward_reference needs objective='trace' (a ratio), got {objective!r}"
                )
        self.reward_reference = reward_reference
        self.family = family
        self.system_seeds = system_seeds
        self.max_sensors = int(max_sensors)
        self.objective = objective
        self.normalize_reward = normalize_reward
        self.describe = describe
        self.action = action
        self.sequential = action == "sequential"
        self.spend_budget = spend_budget
        self.sort_sensors = sort_sensors
        self.order = np.zeros(0, dtype=np.int64)  # slot j -> sensor order[j]
        n = family.state_size
        # the inner env's observation bounds (they depend on n only): read from one built on
        # the family's first system
        inner = SingleAgentEnv(self._sparse_env(family.system(0)), agent="attacker")
        lo, hi = inner.observation_space.low.tolist(), inner.observation_space.high.tolist()
        self.sparse_size = len(lo)
        if self.sequential:
            lo, hi = lo + [0.0] * self.max_sensors, hi + [1.0] * self.max_sensors
        self.description_start = len(lo)
        lo, hi = np.array(lo), np.array(hi)
        if describe:
            dlo, dhi = _description_bounds(n, self.max_sensors, objective)
            lo, hi = np.concatenate([lo, dlo]), np.concatenate([hi, dhi])
        self.observation_space = spaces.Box(lo.astype(np.float32), hi.astype(np.float32))
        n_actions = self.max_sensors + 1 if self.sequential else 2**self.max_sensors
        self.action_space = spaces.Discrete(n_actions)
        self.system: LinearSystem | None = None
        self.system_seed: int | None = None
        self.description: np.ndarray | None = None
        self._inner: SingleAgentEnv | None = None
        self._scale = 1.0
        self._mask = np.zeros(n_actions, dtype=np.int8)
        self._sparse_obs = np.zeros(self.sparse_size)
        self._chosen = 0  # sequential: bitmask picked for the current window step
        self._left = 0  # sequential: budget left after the committed steps
        self._commits = 0  # sequential: window steps played
        self._cache: OrderedDict[int, _Prepared] = OrderedDict()

    def _sparse_env(self, system: LinearSystem) -> FdiaParallelEnv:
        """``sparse_attack_v0``'s env on ``system``, composed from the models.

        (The env modules are a layer above this package, so it is built here, not imported.)
        """
        sc, spec = episode_spec(system, horizon=self.family.horizon, objective=self.objective)
        attack = SparseAttack(self.family.budget)
        return FdiaParallelEnv(sc, attack, PerfectDetection(), spec, name="sparse_attack_v0")

    def _prepared(self, k: int) -> _Prepared:
        """System ``k``'s episode setup, from the cache or computed (and cached) now.

        The system, its sparse env, the slot order, the description and the reward scale
        depend on ``k`` alone, so a system drawn again reuses them (its sparse env is reset).
        """
        cached = self._cache.get(k)
        if cached is not None:
            self._cache.move_to_end(k)
            return cached
        system = self.family.system(k)
        inner = SingleAgentEnv(self._sparse_env(system), agent="attacker")
        P_pred, P, _ = steady_state(system)
        effect = _attack_effect(system, P_pred, P, self.objective)
        order = np.argsort(-effect, kind="stable") if self.sort_sensors else np.arange(system.M)
        description = describe_system(
            system, self.max_sensors, self.objective, order, steady=(P_pred, P), effect=effect
        )
        scale = float(objective(P_pred, self.objective))
        if self.reward_reference is not None:
            ref = self.reward_reference(system, self.family.budget, self.family.horizon)
            if not (isinstance(ref, (int, float, np.floating)) and math.isfinite(ref) and ref > 0):
                raise ValueError(f"reward_reference must return a number > 0, got {ref!r}")
            scale = float(ref)
        prepared = _Prepared(system, inner, order, description, scale)
        self._cache[k] = prepared
        if len(self._cache) > CACHED_SYSTEMS:
            self._cache.popitem(last=False)
        return prepared

    def _observation(self, sparse_obs: np.ndarray, mask: np.ndarray) -> np.ndarray:
        self._sparse_obs = np.asarray(sparse_obs, dtype=np.float64)
        self._mask = np.zeros(self.action_space.n, dtype=np.int8)
        parts = [self._sparse_obs]
        if self.sequential:
            chosen = np.array([(self._chosen >> j) & 1 for j in range(self.max_sensors)])
            if bin(self._chosen).count("1") < self._left:
                self._mask[1 : 1 + self.system.M] = 1 - chosen[: self.system.M]
            last = self._commits == self.family.horizon - 1
            self._mask[0] = 0 if self.spend_budget and last and self._mask[1:].any() else 1
            parts.append(chosen.astype(np.float64))
        else:
            self._mask[: mask.size] = mask
        if self.describe:
            parts.append(self.description)
        obs = np.concatenate(parts)
        low, high = self.observation_space.low, self.observation_space.high
        return np.clip(obs, low, high).astype(np.float32)

    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        """Draw a system and start an episode on it.

        Args:
            seed: Seeds the env's generator (the system draw of this and later resets).
            options: ``{"system_seed": k}`` plays system ``k`` (an integer >= 0).

        Raises:
            ValueError: For options other than ``system_seed`` or a bad ``system_seed``.
        """
        super().reset(seed=seed)
        options = {} if options is None else options
        if not isinstance(options, dict) or set(options) - {"system_seed"}:
            raise ValueError(f"options may only hold 'system_seed', got {options!r}")
        if "system_seed" in options:
            k = check_int("system_seed", options["system_seed"], minimum=0)
        else:
            k = int(self.system_seeds[int(self.np_random.integers(len(self.system_seeds)))])
        self.system_seed = k
        prepared = self._prepared(k)
        self.system, self._inner = prepared.system, prepared.inner
        self.order, self.description = prepared.order, prepared.description
        self._scale = prepared.scale
        self._chosen, self._left, self._commits = 0, self.family.budget, 0
        obs, info = self._inner.reset(seed=int(self.np_random.integers(2**31)))
        out = self._observation(obs, info.get("action_mask"))
        extra = {"system_seed": k, "slot_sensors": self.order.tolist()}
        return out, {**info, "action_mask": self._mask.copy(), **extra}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        """Play ``action``: a bitmask (absent sensors' bits ignored) or a sequential decision."""
        if self._inner is None:
            raise RuntimeError("call reset() before step()")
        a = check_action(self.action_space, action, "attacker")
        if self.sequential:
            if a > 0:  # pick sensor a − 1 for this step; an illegal pick changes nothing
                if self._mask[a]:
                    self._chosen |= 1 << (a - 1)
                out = self._observation(self._sparse_obs, self._mask)
                info = {"action_mask": self._mask.copy(), "system_seed": self.system_seed}
                return out, 0.0, False, False, info
            if not self._mask[0]:  # commit masked (spend_budget): changes nothing
                out = self._observation(self._sparse_obs, self._mask)
                info = {"action_mask": self._mask.copy(), "system_seed": self.system_seed}
                return out, 0.0, False, False, info
            a, self._chosen = self._chosen, 0
            self._left -= bin(a).count("1")
            self._commits += 1
        a &= (1 << self.system.M) - 1
        a = sum(1 << int(self.order[j]) for j in range(self.system.M) if a >> j & 1)
        if self.system.M > MAX_SENSORS:  # the sparse env's MultiBinary action (M > 16)
            a = np.array([(a >> j) & 1 for j in range(self.system.M)], dtype=np.int8)
        obs, reward, term, trunc, info = self._inner.step(a)
        scaled = self.normalize_reward or self.reward_reference is not None
        if scaled and term:  # the terminal reward is the only one
            reward = reward / self._scale if self.objective == "trace" else reward - self._scale
        out = self._observation(obs, info.get("action_mask"))
        info = {**info, "action_mask": self._mask.copy(), "system_seed": self.system_seed}
        return out, float(reward), term, trunc, info

    def action_masks(self) -> np.ndarray:
        """Legal actions now.

        Bitmask: the subsets of present sensors within the budget left. Sequential: commit
        (0) always; pick sensor j (action j + 1) if it is present, not picked yet this step,
        and the picks so far leave budget.
        """
        return self._mask.astype(bool)
