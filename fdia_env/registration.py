"""Gymnasium registration of the single-agent views (``gymnasium.make("fdia_env/...")``)."""

from __future__ import annotations

import gymnasium

# id -> (module whose parallel_env builds the env, learning agent)
GYM_IDS: dict[str, tuple[str, str]] = {
    "fdia_env/DetectionDefender-v0": ("fdia_env.detection_game_v0", "defender"),
    "fdia_env/DetectionAttacker-v0": ("fdia_env.detection_game_v0", "attacker"),
    "fdia_env/SparseAttack-v0": ("fdia_env.sparse_attack_v0", "attacker"),
    "fdia_env/CovarianceAttack-v0": ("fdia_env.covariance_attack_v0", "attacker"),
    "fdia_env/SensorGameAttacker-v0": ("fdia_env.sensor_game_v0", "attacker"),
    "fdia_env/SensorGameDefender-v0": ("fdia_env.sensor_game_v0", "defender"),
}

# envs whose models have no batched implementation (``make_vec`` uses SyncVectorEnv for them)
UNBATCHED: set[str] = set()


def register_envs() -> None:
    """Register every id in :data:`GYM_IDS` (idempotent)."""
    for env_id, (module, agent) in GYM_IDS.items():
        if env_id in gymnasium.registry:
            continue
        batched = module not in UNBATCHED
        gymnasium.register(
            id=env_id,
            entry_point="fdia_env.envs.single_agent:make_single_agent",
            vector_entry_point="fdia_env.vector.env:make_vector" if batched else None,
            kwargs={"module": module, "agent": agent},
        )
