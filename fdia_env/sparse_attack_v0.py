"""``sparse_attack_v0``: sparse sensor-time attacks against a perfectly detecting filter.

## Description

A Kalman filter tracks a system observed by M sensors and has reached steady state at time
K. Over the window K+1..K+N the attacker corrupts measurements; the defender detects every
corrupted measurement and drops it (perfect detection, docs/math.md §4), so the filter runs on the
remaining sensors. The attacker may corrupt at most ``budget`` (c) sensor-time pairs in total
and wants the filter's error covariance at K+N as large as possible. The defender is passive:
the env has the single agent ``"attacker"``.

## Action Space

``Discrete(2**M)``: action ``a`` attacks the sensors whose bits are set (bit 0 = sensor 1);
``0`` attacks nothing. Over-budget rule (``illegal_action``): a subset larger than the budget
left is trimmed to its lowest-numbered sensors that fit (``"trim"``, default), attacks nothing
(``"noop"``) or raises a ``ValueError`` (``"error"``), so an episode never spends more than
``budget``.

That is ``action="bitmask"``, the default (``"auto"``) up to M = 16 sensors. Above 16 (the
power-grid presets have 34 to 304 meters) ``"auto"`` gives ``MultiBinary(M)`` (entry i = 1
attacks sensor i; no action mask, so the observation is the plain ``Box``: MaskablePPO's
per-entry MultiBinary mask cannot express a budget, and Gymnasium's MultiBinary mask has another
shape; train it with PPO/A2C); ``action="single"`` gives ``Discrete(M + 1)`` (0 = no attack, j =
sensor j alone, masked to 0 once the budget is spent). The same over-budget rule applies to
every format (see :class:`fdia_env.attacks.SparseAttack`).

``action="sequential"`` (any M; the MaskablePPO choice on the grid presets) builds each window
step's set one sensor per decision: ``Discrete(M + 1)``, action j adds sensor j, action 0 stops
and takes the window step with the set built. The ``(M + 1,)`` mask forbids a sensor already in
the set and every sensor once the set uses up the budget left; decisions with stop as the only
legal action are played by the env, so an episode takes at most N + c decisions. Rewards are
paid at the stops, so every attack set of the other formats is reachable and returns the same
value. An action outside the mask acts as stop (``"trim"``, ``"noop"``) or raises
(``"error"``). The observation ``Box`` adds M entries (1 = in the set being built) and the
budget left after the set; see ``fdia_env.envs.sequential``. PettingZoo parallel, AEC, the
Gymnasium view (``action_masks()``) and the native vector env (``gymnasium.make_vec(...,
vectorization_mode="vector_entry_point", action="sequential")``, numpy or torch); its
``max_cycles`` counts decisions. ``sparse_attack_v1`` makes it the default above 16 sensors.
``order="plan"`` (sequential only) changes the decision order: the (sensor, window step) pairs of
the whole horizon are picked first (``Discrete(N·M + 1)``, action ``1 + k·M + j - 1`` = sensor
j at window step k + 1, the ``(N·M + 1,)`` mask forbidding a pair in the plan and every pair
once the plan uses the budget), then stop plays the plan out; same rewards and reachable sets.
``order="increasing"`` is ``"plan"`` with the picks in increasing order (the mask also forbids
every pair at or below the last pick), so each plan has one sequence of picks.
``groups="state"`` (plan-first orders only; default None) adds N·n group actions after the
pairs' (``Discrete(N·M + 1 + N·n)``): action ``N·M + 1 + k·n + j`` adds every pair of window
step K+1+k whose sensor sees state j, the smallest set that biases that state alone (legal in
increasing order of the groups, when it adds 1 to budget-left new pairs). Same observation,
rewards and reachable sets; ``train.py`` trains the ``dc-ieee14-50`` preset with it, whose
optimum needs all four meters of one bus at once (see ``fdia_env.envs.sequential``).

## Observation Space

``Dict(observation=Box(float32), action_mask=Box(0, 1, (2**M,), int8))``, where
``action_mask[a] = 1`` iff subset ``a`` fits the budget left. ``observation`` holds:

| index | feature | range |
|---|---|---|
| 0 | steps left / N | [0, 1] |
| 1..n | log(M_ii / P_ii at window start) (error variance growth) | [-30, 30] |
| next n(n−1)/2 | correlations of the error covariance (i < j) | [-1, 1] |
| (sampled only) | normalised innovation squared per measurement, last step | [0, 1000] |
| last | budget left / budget | [0, 1] |

## Rewards

Φ = tr or log det of the actual error covariance (``dynamics="expected"``) or the squared
estimation error (``"sampled"``). ``reward_mode="terminal"`` pays Φ(P[K+N|K+N]) at the last
step, so the episode return is the objective of docs/math.md §4; ``"shaped"`` pays increments;
``"per_step"`` pays Φ every step.

## Starting State

The filter covariance is the steady state with all sensors (``warmup="steady"``), or the prior
run ``warmup`` clean steps. In sampled dynamics the true state is drawn around the estimate.

## Episode End

Terminates after N steps. No truncation.

## Arguments

``scenario`` (preset name, Scenario or LinearSystem; default ``"ch4-position"``), ``budget``
(c, default the preset's), ``horizon`` (N, default the preset's), ``objective``,
``reward_mode``, ``dynamics``, ``warmup``, ``render_mode`` (``"human"`` | ``"ansi"`` |
``"rgb_array"``), ``action`` (``"auto"`` | ``"bitmask"`` | ``"multibinary"`` | ``"single"``
| ``"sequential"``),
``illegal_action`` (``"trim"`` | ``"noop"`` | ``"error"``), ``max_cycles``.

## Version History

- v0: initial release. Infos with the same keys at reset and at every step, ``max_cycles``,
  ``render_mode="human"``. The opt-in ``action="sequential"`` format (defaults unchanged): its
  ``max_cycles`` counts decisions. Superseded by ``sparse_attack_v1`` (sequential by default
  above 16 sensors); ``gymnasium.make("fdia_env/SparseAttack-v0")`` says so (Gymnasium's
  out-of-date notice).

## Example

>>> from fdia_env import sparse_attack_v0
>>> env = sparse_attack_v0.parallel_env(scenario="ch4-position", budget=5, horizon=6)
>>> obs, infos = env.reset(seed=0)
>>> plan = [0, 0, 1, 1, 1, 3]  # sensor 1 at K+3..K+6, sensor 2 at K+6
>>> for a in plan:
...     obs, rewards, terms, truncs, infos = env.step({"attacker": a})
>>> round(rewards["attacker"], 4)
0.0328
"""

from __future__ import annotations

from typing import Any

from fdia_env._validation import check_choice
from fdia_env.attacks import SparseAttack
from fdia_env.attacks.sparse import ACTION_FORMATS
from fdia_env.defenses import PerfectDetection
from fdia_env.envs.factory import (
    EPISODE_ORDER,
    aec_views,
    episode_spec,
    scenario_default,
    with_episode_parameters,
)
from fdia_env.envs.parallel import FdiaParallelEnv
from fdia_env.envs.sequential import ORDERS, SequentialSetEnv, check_groups
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

NAME = "sparse_attack_v0"


@with_episode_parameters(
    "scenario", "budget", *EPISODE_ORDER, "illegal_action", "action", "order", "groups"
)
def parallel_env(
    scenario: str | Scenario | LinearSystem = "ch4-position",
    budget: int | None = None,
    render_mode: str | None = None,
    illegal_action: str = "trim",
    action: str = "auto",
    order: str = "time",
    groups: str | None = None,
    **episode: Any,
) -> FdiaParallelEnv | SequentialSetEnv:
    """The PettingZoo ``ParallelEnv`` (see the module docstring).

    ``action="sequential"`` returns a ``fdia_env.envs.sequential.SequentialSetEnv``
    over the ``"multibinary"`` env (see the module docstring's Action Space), its decisions in
    ``order`` (``"time"``; ``"plan"``: the pairs of the whole horizon first; ``"increasing"``:
    as ``"plan"``, the pairs picked in increasing order), with group actions when ``groups`` is
    ``"state"`` (plan-first orders only: each adds the pairs of one window step whose sensors see
    one state; see the module docstring). The episode
    parameters (``horizon``, ``objective``, ...) are those of
    :data:`fdia_env.envs.factory.EPISODE_PARAMETERS`.

    Raises:
        ValueError: For ``order="plan"`` with another format than ``"sequential"``, ``groups``
            with another order than a plan-first one (and for any other bad option, naming it).
    """
    check_choice("action", action, (*ACTION_FORMATS, "sequential"))  # every format in the error
    check_choice("order", order, ORDERS)
    if order != "time" and action != "sequential":
        raise ValueError(
            f"order={order!r} applies to action='sequential' only, got action={action!r}"
        )
    check_groups(groups, order)
    if action == "sequential":
        inner = parallel_env(
            scenario,
            budget,
            render_mode=render_mode,
            illegal_action="error",
            action="multibinary",
            **episode,
        )
        return SequentialSetEnv(inner, illegal_action=illegal_action, order=order, groups=groups)
    sc, spec = episode_spec(scenario, **episode)
    attack = SparseAttack(
        scenario_default(sc, "budget", budget), action=action, illegal_action=illegal_action
    )
    return FdiaParallelEnv(
        sc,
        attack,
        PerfectDetection(),
        spec,
        render_mode=render_mode,
        name=NAME,
        max_cycles=episode["max_cycles"],
    )


raw_env, env = aec_views(parallel_env)
