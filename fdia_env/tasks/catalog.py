"""The definitions of the benchmark tasks (what to build; the references are stored apart).

Each :class:`TaskSpec` says how to build a task's env. Its reference values live in
``references.json`` beside this module (computed by ``python -m agents.bench compute``), and
its difficulty is graded from them (:meth:`fdia_env.tasks.task.References.grade`).
Adding a task is one :class:`TaskSpec` here plus ``python -m agents.bench compute --task NAME``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

SPARSE = "fdia_env/SparseAttack-v0"
COVARIANCE = "fdia_env/CovarianceAttack-v0"
GAME_ATTACKER = "fdia_env/SensorGameAttacker-v0"
GAME_DEFENDER = "fdia_env/SensorGameDefender-v0"
DETECTION_DEFENDER = "fdia_env/DetectionDefender-v0"
DETECTION_ATTACKER = "fdia_env/DetectionAttacker-v0"
STEALTH_ATTACKER = "fdia_env/StealthAttack-v0"
STEALTH_DYNAMIC = "fdia_env/StealthDynamic-v0"
STEALTH_DYNAMIC_DEFENDER = "fdia_env/StealthDynamicDefender-v0"
FAMILY_ID = "fdia_env/SystemFamily-v0"
FAMILY_ENTRY_POINT = "fdia_env.envs.system_family:SystemFamilyEnv"


@dataclass(frozen=True)
class TaskSpec:
    """How to build one task (see :class:`fdia_env.tasks.task.Task` for the fields)."""

    name: str
    family: str
    player: str
    env_id: str
    env_kwargs: Mapping[str, Any]
    module: str | None
    description: str
    episodes: int = 10
    entry_point: str | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)


def _sparse(
    instance: str,
    scenario: Any,
    budget: int,
    horizon: int,
    objective: str = "trace",
    episodes: int = 10,
    **kwargs: Any,
) -> TaskSpec:
    what = "log det" if objective == "logdet" else "trace"
    label = getattr(scenario, "description", scenario)
    return TaskSpec(
        f"sparse/{instance}-v0",
        "sparse",
        "attacker",
        SPARSE,
        {
            "scenario": scenario,
            "budget": budget,
            "horizon": horizon,
            "objective": objective,
            **kwargs,
        },
        "fdia_env.sparse_attack_v0",
        f"{label}: drop at most {budget} sensor-time pairs over {horizon} steps under perfect "
        f"detection, maximise the {what} of the error covariance at the window's end",
        episodes,
    )


def _tracking(seed: int) -> Any:
    """System ``seed`` of the random tracking family with 6 sensors (a fixed Scenario)."""
    from fdia_env.envs.system_family import TrackingFamily

    return TrackingFamily(num_sensors=6, budget=4, horizon=4).scenario(seed)


def _covariance(instance: str, scenario: str, power: float, objective: str) -> TaskSpec:
    what = "log det" if objective == "logdet" else "trace"
    return TaskSpec(
        f"covariance/{instance}-v0",
        "covariance",
        "attacker",
        COVARIANCE,
        {"scenario": scenario, "power": power, "objective": objective},
        "fdia_env.covariance_attack_v0",
        f"{scenario}: one bias covariance of power {power:g} against the unaware filter, "
        f"maximise the {what} of the actual error covariance",
        episodes=10,
    )


def _game(instance: str, scenario: str, player: str, **kwargs: Any) -> TaskSpec:
    env_id = GAME_ATTACKER if player == "attacker" else GAME_DEFENDER
    return TaskSpec(
        f"sensor-game/{instance}-{player}-v0",
        "sensor-game",
        player,
        env_id,
        {"scenario": scenario, **kwargs},
        "fdia_env.sensor_game_v0",
        f"{scenario}: the {player} of the one-shot sensor-selection game"
        + "".join(f", {k} {v}" for k, v in kwargs.items())
        + ", scored by its exploitability (worst-case return against a best response)",
        episodes=10,
    )


def _bayes(instance: str, scenario: str, player: str, model: str, **kwargs: Any) -> TaskSpec:
    env_id = GAME_ATTACKER if player == "attacker" else GAME_DEFENDER
    return TaskSpec(
        f"incomplete-information/{instance}-{player}-v0",
        "incomplete-information",
        player,
        env_id,
        {
            "scenario": scenario,
            "types": ["independent", "dependent"],
            "priors": [0.5, 0.5],
            "attacker_model": model,
            **kwargs,
        },
        "fdia_env.sensor_game_v0",
        f"{scenario}: the {player} of the sensor game where nature draws the attacker's "
        f"allocation rule ({model} attacker), scored by its exploitability in the Bayesian game",
        episodes=10,
    )


def _detection(instance: str, scenario: str, power: float, player: str = "defender") -> TaskSpec:
    if player == "defender":
        env_id = DETECTION_DEFENDER
        what = f"the detector's threshold against an attack of power {power:g}, minimise the "
        what += "Bayes cost"
    else:
        env_id = DETECTION_ATTACKER
        what = (
            f"the attacker's probability and bias covariance (power {power:g}) against the "
            "quadratic detector at its fixed threshold s, maximise the Bayes cost"
        )
    return TaskSpec(
        f"detection-game/{instance}-{player}-v0",
        "detection-game",
        player,
        env_id,
        {"scenario": scenario, "power": power, "criterion": "bayes_cost"},
        "fdia_env.detection_game_v0",
        f"{scenario}: {what}",
        episodes=10,
    )


def _stealth(instance: str, scenario: str, budget: int) -> TaskSpec:
    return TaskSpec(
        f"stealth/{instance}-v0",
        "stealth",
        "attacker",
        STEALTH_ATTACKER,
        {"scenario": scenario, "budget": budget, "action": "shift", "dynamics": "expected"},
        "fdia_env.stealth.stealth_attack_v0",
        f"{scenario}: shift state estimates past the chi2 bad-data test with at most {budget} "
        "meters, maximise the expected undetected shift",
        episodes=10,
    )


def _stealth_box(
    instance: str, scenario: str, budget: int, a_max: float, protected: tuple[str, ...] = ()
) -> TaskSpec:
    kwargs: dict[str, Any] = {
        "scenario": scenario,
        "budget": budget,
        "action": "box_shift",
        "a_max": a_max,
        "dynamics": "expected",
    }
    guarded = ""
    if protected:
        kwargs["protected"] = list(protected)
        guarded = f" (meter{'s' if len(protected) > 1 else ''} {', '.join(protected)} protected)"
    return TaskSpec(
        f"stealth/{instance}-v0",
        "stealth",
        "attacker",
        STEALTH_ATTACKER,
        kwargs,
        "fdia_env.stealth.stealth_attack_v0",
        f"{scenario}: shift a set of state estimates together, as far as injections of at most "
        f"{a_max:g} pu allow, past the chi2 bad-data test with at most {budget} meters"
        f"{guarded}; maximise the expected undetected shift",
        episodes=10,
    )


def _stealth_dynamic(instance: str, scenario: str, a_max: float, horizon: int) -> TaskSpec:
    return TaskSpec(
        f"stealth/{instance}-v0",
        "stealth",
        "attacker",
        STEALTH_DYNAMIC,
        {
            "scenario": scenario,
            "action": "bias",
            "a_max": a_max,
            "horizon": horizon,
            "dynamics": "expected",
        },
        "fdia_env.stealth.stealth_dynamic_v0",
        f"{scenario}: bias every sensor by at most {a_max:g} innovation standard deviations per "
        f"step for {horizon} steps against the Kalman filter's windowed chi2 detector, maximise "
        "the expected undetected error (trace of its covariance, summed over the steps)",
        episodes=10,
    )


def rotating_bias(sensors: int, horizon: int) -> Any:
    """The attacker that biases sensor ``k mod sensors`` by ``+a_max`` at step k (a schedule)."""
    import numpy as np

    from fdia_env.stealth.dynamic_policy import ScheduledPolicy

    table = np.zeros((horizon, sensors))
    table[np.arange(horizon), np.arange(horizon) % sensors] = 1.0
    return ScheduledPolicy(table)


def _stealth_protect(
    instance: str, scenario: str, sensors: int, a_max: float, horizon: int
) -> TaskSpec:
    return TaskSpec(
        f"stealth/{instance}-defender-v0",
        "stealth",
        "defender",
        STEALTH_DYNAMIC_DEFENDER,
        {
            "scenario": scenario,
            "action": "bias",
            "a_max": a_max,
            "horizon": horizon,
            "dynamics": "expected",
            "defender": "protect",
            "protect_budget": 1,
            "false_alarm_cost": 0.0,
            "opponent": rotating_bias(sensors, horizon),
        },
        "fdia_env.stealth.stealth_dynamic_v0",
        f"{scenario}: protect one sensor per step against an attacker that biases sensor "
        f"k mod {sensors} by {a_max:g} innovation standard deviations at step k, for {horizon} "
        "steps, under the windowed chi2 detector; minimise the attacker's expected undetected "
        "error (an alarm stops its payoff, so letting a bias through can pay)",
        episodes=10,
    )


def _family(instance: str, objective: str, first: int, count: int, **family: Any) -> TaskSpec:
    from fdia_env.envs.system_family import TrackingFamily

    return TaskSpec(
        f"system-family/{instance}-v0",
        "system-family",
        "attacker",
        FAMILY_ID,
        {
            "family": TrackingFamily(**family),
            "system_seeds": range(first, first + count),
            "objective": objective,
        },
        None,
        f"one sparse attacker for {count} random tracking systems ({family}), a system drawn "
        "at every reset",
        episodes=100,
        entry_point=FAMILY_ENTRY_POINT,
    )


SPECS: tuple[TaskSpec, ...] = (
    _sparse("ch4-position", "ch4-position", 5, 6),
    _sparse("ch4-position-long", "ch4-position", 8, 10),
    _sparse("ch4-pv-case1-logdet", "ch4-pv-case1", 5, 6, "logdet"),
    _sparse("ch4-pv-case3-logdet", "ch4-pv-case3", 5, 6, "logdet"),
    _sparse("ch4-random", "ch4-random", 10, 6),
    _sparse("ch4-random-logdet", "ch4-random", 5, 6, "logdet"),
    _sparse("tracking-m6-1000004", _tracking(1_000_004), 4, 4),
    _sparse("tracking-m6-1000006", _tracking(1_000_006), 4, 4),
    _sparse("tracking-m6-1000007", _tracking(1_000_007), 4, 4),
    _sparse("tracking-m6-1000037", _tracking(1_000_037), 4, 4),
    _sparse("ieee14-logdet", "grid-ieee14", 5, 1, "logdet", action="sequential"),
    _sparse("ieee14-logdet-window", "grid-ieee14", 4, 3, "logdet", action="sequential"),
    _sparse("ieee14", "grid-ieee14", 3, 2, action="sequential"),
    _covariance("ch2-position", "ch2-position", 3000.0, "trace"),
    _covariance("ch2-position-logdet", "ch2-position", 3000.0, "logdet"),
    _covariance("ch2-pv-1", "ch2-pv-1", 3000.0, "trace"),
    _covariance("ch2-pv-2", "ch2-pv-2", 3000.0, "trace"),
    _covariance("ch2-pv-2-logdet", "ch2-pv-2", 3000.0, "logdet"),
    _covariance("ieee14", "grid-ieee14", 0.01, "trace"),
    _covariance("ieee14-logdet", "grid-ieee14", 0.01, "logdet"),
    _game("ch5-game", "ch5-game", "attacker", power=100.0),
    _game("ch5-game", "ch5-game", "defender", power=100.0),
    _game("m10", "game-m10", "attacker", power=100.0),
    _game("m10", "game-m10", "defender", power=100.0),
    _game("m10-strong", "game-m10", "defender", power=1000.0),
    _game("m10-strong-dependent", "game-m10", "attacker", power=1000.0, allocation="dependent"),
    _game("m10-strong-dependent", "game-m10", "defender", power=1000.0, allocation="dependent"),
    _game("m10-strong-k3", "game-m10", "defender", power=1000.0, max_subset_size=3),
    _game(
        "m10-strong-dependent-k2",
        "game-m10",
        "defender",
        power=1000.0,
        allocation="dependent",
        max_subset_size=2,
    ),
    _game("ieee14", "grid-ieee14", "attacker"),
    _game("ieee14", "grid-ieee14", "defender"),
    _game("ieee118", "grid-ieee118", "attacker"),
    _game("ieee118", "grid-ieee118", "defender"),
    _game("ieee14-strong-k1", "grid-ieee14", "attacker", power=1.0, max_subset_size=1),
    _game("ieee30-strong", "grid-ieee30", "attacker", power=1.0, max_subset_size=1),
    _game("dc-ieee14-50-strong", "dc-ieee14-50", "attacker", power=1.0, max_subset_size=1),
    _bayes("ch5-game-informed", "ch5-game", "attacker", "informed", power=100.0),
    _bayes("ch5-game-informed", "ch5-game", "defender", "informed", power=100.0),
    _bayes("ch5-game-uninformed", "ch5-game", "attacker", "uninformed", power=100.0),
    _bayes("ch5-game-uninformed", "ch5-game", "defender", "uninformed", power=100.0),
    _bayes("m10-informed", "game-m10", "defender", "informed", power=100.0),
    _bayes("m10-strong-informed", "game-m10", "defender", "informed", power=1000.0),
    _detection("ch3-static", "ch3-static", 240.0),
    _detection("ch3-tracking", "ch3-tracking", 7.5),
    _detection("ch3-static", "ch3-static", 240.0, "attacker"),
    _detection("ch3-tracking", "ch3-tracking", 7.5, "attacker"),
    _stealth("ieee14-b3", "grid-ieee14", 3),
    _stealth_box("ieee14-box-b12", "grid-ieee14", 12, 0.05),
    _stealth_box("ieee14-box-b8-protected", "grid-ieee14", 8, 0.05, ("trafo3@6",)),
    _stealth_box("ieee14-box-b12-protected", "grid-ieee14", 12, 0.05, ("trafo3@6",)),
    _stealth_dynamic("ch4-position-dynamic-bias", "ch4-position", 0.25, 10),
    _stealth_protect("ch4-position-dynamic-protect", "ch4-position", 3, 1.0, 6),
    _family("tracking-m6", "trace", 1_000_000, 20, num_sensors=6, budget=4, horizon=4),
)
