"""Valid-value strategies for every env constructor's keyword arguments (property suite)."""

from __future__ import annotations

from typing import Any

import numpy as np
from hypothesis import strategies as st
from prop_support import matrix_values

from fdia_env import scenarios
from fdia_env.attacks import CovarianceAttack, SparseAttack
from fdia_env.defenses import PerfectDetection, UnawareFilter
from fdia_env.registration import kalman_env_names

MODULES = tuple(kalman_env_names())  # the table's Kalman-filter envs (each needs PARAMS)
SMALL_SCENARIOS = [  # ch4-random, game-m10: 10 sensors
    n for n in scenarios.names() if n not in ("ch4-random", "game-m10")
]

scenario_values = st.one_of(
    st.sampled_from(SMALL_SCENARIOS),
    st.builds(lambda name: scenarios.get(name), st.sampled_from(SMALL_SCENARIOS)),
    st.builds(lambda name: scenarios.get(name).system, st.sampled_from(SMALL_SCENARIOS)),
)
power_values = st.one_of(
    st.none(),
    st.floats(1e-12, 1e12),
    st.sampled_from([1.0, 100.0, 3000.0, 1e12]),
    st.integers(1, 10**6),
)
warmup_values = st.one_of(st.none(), st.just("steady"), st.integers(0, 150))
COMMON = {
    "scenario": scenario_values,
    "horizon": st.one_of(st.none(), st.integers(1, 12)),
    "objective": st.sampled_from(["trace", "logdet"]),
    "reward_mode": st.sampled_from(["terminal", "shaped", "per_step"]),
    "dynamics": st.sampled_from(["expected", "sampled"]),
    "warmup": warmup_values,
    "render_mode": st.sampled_from([None, "ansi", "rgb_array"]),
    "max_cycles": st.one_of(st.none(), st.integers(1, 12)),
}


def _pick(*names: str) -> dict[str, st.SearchStrategy[Any]]:
    return {name: COMMON[name] for name in names}


PARAMS: dict[str, dict[str, st.SearchStrategy[Any]]] = {
    "sparse_attack_v0": {
        **_pick(*COMMON),
        "budget": st.one_of(st.none(), st.integers(0, 12)),
        "illegal_action": st.sampled_from(["trim", "error", "noop"]),
    },
    "sparse_attack_v1": {  # v0's options; "auto" is sequential above 16 sensors
        **_pick(*COMMON),
        "budget": st.one_of(st.none(), st.integers(0, 12)),
        "illegal_action": st.sampled_from(["trim", "error", "noop"]),
    },
    "sparse_attack_v2": {  # v1's options; the sequential format's order is "plan" by default
        **_pick(*COMMON),
        "budget": st.one_of(st.none(), st.integers(0, 12)),
        "illegal_action": st.sampled_from(["trim", "error", "noop"]),
    },
    "covariance_attack_v0": {
        **_pick(*COMMON),
        "power": power_values,
        "structure": st.sampled_from(["full", "diagonal"]),
        "power_mode": st.sampled_from(["per_step", "budget"]),
        "weight": st.one_of(st.none(), matrix_values()),
    },
    "sensor_game_v0": {
        **_pick("scenario", "reward_mode", "dynamics", "render_mode", "max_cycles"),
        "power": power_values,
        "allocation": st.sampled_from(["independent", "dependent"]),
        "rounds": st.one_of(st.none(), st.integers(1, 6)),
    },
    "detection_game_v0": {
        **_pick(*COMMON),
        "power": st.one_of(st.floats(1e-12, 1e12), st.sampled_from([1.0, 100.0, 1e12])),
        "statistic": st.sampled_from(["quadratic", "chi2"]),
        "on_detect": st.sampled_from(["discard", "incorporate"]),
        "criterion": st.sampled_from(["mse", "bayes_cost"]),
        "assumed_sigma": st.one_of(st.none(), matrix_values()),
    },
    "fdia_v0": {
        **_pick(*COMMON),
        "attack": st.one_of(
            st.sampled_from(["sparse", "covariance", "subset", "probabilistic"]),
            st.builds(SparseAttack, st.integers(0, 3)),
            st.builds(CovarianceAttack, st.sampled_from([1.0, 100.0])),
        ),
        "defense": st.one_of(
            st.sampled_from(["perfect_detection", "unaware", "sensor_selection"]),
            st.builds(PerfectDetection),
            st.builds(UnawareFilter),
        ),
        "attack_kwargs": st.one_of(
            st.none(),
            st.fixed_dictionaries({}, optional={"budget": st.integers(0, 4)}),
            st.fixed_dictionaries({}, optional={"power": st.floats(1e-6, 1e6)}),
            st.dictionaries(
                st.sampled_from(["budget", "power", "structure", "bogus"]),
                st.integers(-2, 5),
                max_size=2,
            ),
        ),
        "defense_kwargs": st.one_of(st.none(), st.just({}), st.just({"bogus": 1})),
    },
}

# the Gymnasium entry points' own arguments (on top of the module's)
VIEW_PARAMS = {
    "agent": st.sampled_from(["attacker", "defender"]),
}
VECTOR_PARAMS = {
    "agent": st.sampled_from(["attacker", "defender"]),
    "autoreset_mode": st.sampled_from(["NextStep", "SameStep", "next_step"]),
    "max_episode_steps": st.one_of(st.none(), st.integers(1, 10)),
}


def random_seed() -> st.SearchStrategy[int]:
    """Seeds for reset."""
    return st.integers(0, 2**32 - 1)


def unit_actions(shape: tuple[int, ...]) -> st.SearchStrategy[np.ndarray]:
    """Arrays in [-1, 1] of ``shape`` (float32)."""
    return st.lists(
        st.floats(-1.0, 1.0, width=32), min_size=int(np.prod(shape)), max_size=int(np.prod(shape))
    ).map(lambda v: np.array(v, dtype=np.float32).reshape(shape))
