"""``sensor_game_v0``: the zero-sum sensor-selection game of docs/math.md §5.

## Description

Both players pick a non-empty subset of the M sensors. The defender's filter runs on its subset
D and is in steady state when the attack comes; the attacker spends its power a² on its subset A
by the ``allocation`` rule (``"independent"``: all on the smallest-variance sensor of A;
``"dependent"``: correlation 1 with ``σ_b,i ∝ 1/σ_i²``); only the biases on A ∩ D reach the
filter, which is unaware of them. The attacker is paid ``L[D, A] = tr(P_D + W_D Σ_{A∩D} W_D')``
and the defender minus that. By default the game is one-shot (``rounds=1``); with ``rounds > 1``
it is repeated and each player observes the other's last subset. The analytic solution is the LP
equilibrium of ``baselines.game``.

### Incomplete information (``types=``)

``types=("independent", "dependent")`` with ``priors=(p_1, p_2)`` (default uniform) is the
Bayesian game of docs/math.md §5: at every reset nature draws the attacker's type (its allocation
rule) from the env's seeded generator; the defender never observes it (neither in its
observation nor in its infos). With ``attacker_model="informed"`` (default) the attacker
observes its type and may condition on it; with ``"uninformed"`` it does not (the literature's
formulation, whose game is the matrix game on ``L̄ = Σ_s p_s L_s``). The type is in the
attacker's infos (``info["type"]``, an index into ``types``) and can be forced for one episode
with ``reset(options={"attacker_type": "dependent"})`` (a name or an index; nature's uniform is
drawn either way, so the episode's other draws do not change). The exact game and its
equilibrium are ``baselines.game.bayesian_game(scenario, types, priors, attacker_model)``, the
reference ``agents.registry`` scores learned policies against (exploitability).

## Action Space

``Discrete(2**M − 1)`` for each player: index j is the j-th subset by size then lexicographic
(for M = 3: z1, z2, z3, z1z2, z1z3, z2z3, z1z2z3; see ``fdia_env.attacks.subsets``).

With ``max_subset_size=k`` (for large M, where 2**M − 1 is astronomically large) the attacker's
strategies are the subsets of at most k sensors and the defender's those that leave out at most
k sensors (sizes M − k..M), each in the same size-then-lexicographic order: e.g. k = 1 gives the
attacker ``Discrete(M)`` (one sensor) and the defender ``Discrete(M + 1)`` (drop one sensor,
then the full set last). The power-grid presets set k (``scenario.extra["max_subset_size"]``);
``max_subset_size=None`` takes the preset's k, or every subset when the preset has none.

``action="sequential"`` (any M; the MaskablePPO choice where the subsets are too many) builds
each player's subset one sensor per decision: ``Discrete(M + 1)`` for each, 0 = stop, j = pick
sensor j. The attacker picks the sensors of A; the defender picks the sensors it leaves out of
D, so with ``max_subset_size=k`` each player takes at most k picks. Both decide at every
decision (the game stays simultaneous) and the round is played once both have stopped; a
player that has stopped waits, sending stop. The ``(M + 1,)`` mask (in the observation dict,
and ``action_masks()``) forbids a sensor already picked, every sensor once the player's picks
are used up, the attacker's stop before its first pick, and everything but stop while waiting;
a player with stop as its only legal action has stopped. Rewards are paid when the round is
played, so every pair of subsets of the subset format is reachable and pays the same.
``illegal_action``: an action outside the mask raises (``"error"``), or acts as stop
(``"trim"``, default, and ``"noop"``; an illegal stop or a waiting player's pick is ignored).
The observation ``Box`` adds M entries (1 = picked by the player this round). The Gymnasium
views take ``opponent=`` a policy of the subset format (default the uniform mix), asked once
per round as in the subset format. See ``fdia_env.envs.sequential``. The native vector env
(``gymnasium.make_vec(..., vectorization_mode="vector_entry_point", action="sequential")``,
numpy or torch) is :class:`fdia_env.vector.sequential_game.SequentialGameVectorEnv`.

## Observation Space

``Box(float32)``: steps left / rounds, log variance growth and correlations of the actual error
covariance after the last round (as in every fdia_env env; NIS too in sampled mode), then the
other player's last subset as a 0/1 indicator per sensor. With ``types`` and an informed
attacker, the attacker's observation ends with its type as a one-hot vector of length S.

## Rewards

``reward_mode="per_step"`` (default) pays ±L[D, A] every round (expected dynamics) or ± the
squared estimation error (sampled); ``"terminal"`` pays the last round only.

## Episode End

Terminates after ``rounds`` rounds.

## Arguments

``scenario`` (default ``"ch5-game"``), ``power`` (default the preset's), ``allocation``
(default ``"independent"``; not with ``types``), ``types``, ``priors``, ``attacker_model``,
``rounds`` (default 1, or ``max_cycles`` when only that is given), ``reward_mode``,
``dynamics``, ``render_mode`` (``"human"`` | ``"ansi"`` | ``"rgb_array"``), ``max_cycles``,
``max_subset_size``, ``action`` (``"subset"``, the default, or ``"sequential"``),
``illegal_action`` (``"sequential"`` only).

Gymnasium views: ``fdia_env/SensorGameAttacker-v0`` and ``fdia_env/SensorGameDefender-v0``, the
other player fixed to ``opponent=`` (any SB3-style policy, e.g.
``fdia_env.envs.opponents.FixedMix(probs)``), by default the uniform mix.

## Version History

- v0: initial release. Infos with the same keys at reset and at every step, ``max_cycles``,
  ``render_mode="human"``. ``types``, ``priors``, ``attacker_model`` (incomplete
  information); the default (no types) is unchanged. ``action="sequential"`` (one sensor per
  decision, masked); the default format is unchanged.

## Example

>>> from fdia_env import sensor_game_v0
>>> env = sensor_game_v0.parallel_env(scenario="ch5-game")
>>> _ = env.reset(seed=0)
>>> _, rewards, *_ = env.step({"attacker": 0, "defender": 0})  # both pick z1
>>> round(rewards["attacker"], 1)
25.4
"""

from __future__ import annotations

from collections.abc import Sequence

from fdia_env._validation import check_choice, check_int
from fdia_env.attacks.subset import SubsetAttack
from fdia_env.attacks.typed import ATTACKER_MODELS, TypedSubsetAttack
from fdia_env.defenses.selection import SensorSelection
from fdia_env.envs.factory import aec_views, episode_spec, scenario_default
from fdia_env.envs.parallel import FdiaParallelEnv
from fdia_env.envs.sequential import SequentialSubsetEnv
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

NAME = "sensor_game_v0"
ACTIONS = ("subset", "sequential")
"""Action formats: a subset index per round, or the subset built one sensor per decision."""


def parallel_env(
    scenario: str | Scenario | LinearSystem = "ch5-game",
    power: float | None = None,
    allocation: str | None = None,
    rounds: int | None = None,
    reward_mode: str = "per_step",
    dynamics: str = "expected",
    render_mode: str | None = None,
    max_cycles: int | None = None,
    max_subset_size: int | None = None,
    types: Sequence[str] | None = None,
    priors: Sequence[float] | None = None,
    attacker_model: str = "informed",
    action: str = "subset",
    illegal_action: str | None = None,
) -> FdiaParallelEnv | SequentialSubsetEnv:
    """The PettingZoo ``ParallelEnv`` (see the module docstring).

    ``action="sequential"`` returns a ``fdia_env.envs.sequential.SequentialSubsetEnv`` over
    the subset-format env (see the module docstring's Action Space); ``illegal_action``
    (``"trim"`` default, ``"noop"``, ``"error"``) is its rule and needs that format.

    Raises:
        ValueError: Naming the parameter, e.g. ``allocation`` together with ``types``,
            ``priors`` or an ``"uninformed"`` ``attacker_model`` without ``types``, priors of
            the wrong length, negative or not summing to 1, an unknown or repeated type.
    """
    check_choice("action", action, ACTIONS)
    check_choice("attacker_model", attacker_model, ATTACKER_MODELS)
    if action == "sequential":
        inner = parallel_env(
            scenario, power, allocation, rounds, reward_mode, dynamics, render_mode,
            max_cycles, max_subset_size, types, priors, attacker_model,
        )  # fmt: skip
        return SequentialSubsetEnv(inner, "trim" if illegal_action is None else illegal_action)
    if illegal_action is not None:
        raise ValueError(
            f"illegal_action applies to action='sequential' only (every subset index of the "
            f"'subset' format is legal), got illegal_action={illegal_action!r}"
        )
    if types is None:
        if priors is not None:
            raise ValueError("priors needs types: pass types=(...) with one prior per type")
        if attacker_model != "informed":
            raise ValueError(
                f"attacker_model={attacker_model!r} needs types: without types there is one "
                "attacker type and nothing to be informed of"
            )
    elif allocation is not None:
        raise ValueError(
            f"pass allocation (one rule for every episode) or types (nature draws the rule), "
            f"not both: got allocation={allocation!r} and types={types!r}"
        )
    if rounds is not None:
        rounds = check_int("rounds", rounds, minimum=1)
    sc, spec = episode_spec(
        scenario,
        horizon=rounds,
        max_cycles=max_cycles,
        default_horizon=1,
        warmup="steady",
        objective="trace",
        reward_mode=reward_mode,
        dynamics=dynamics,
    )
    if max_subset_size is None:
        max_subset_size = sc.extra.get("max_subset_size")
    power = scenario_default(sc, "power", power)
    if types is None:
        attack = SubsetAttack(
            power, allocation="independent" if allocation is None else allocation,
            max_subset_size=max_subset_size,
        )  # fmt: skip
    else:
        attack = TypedSubsetAttack(power, types, priors, attacker_model, max_subset_size)
    defense = SensorSelection(max_subset_size)
    return FdiaParallelEnv(
        sc, attack, defense, spec, render_mode=render_mode, name=NAME, max_cycles=max_cycles
    )


raw_env, env = aec_views(parallel_env)
