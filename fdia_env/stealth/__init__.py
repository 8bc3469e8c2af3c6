"""Stealthy false-data injection against bad-data detection on static DC state estimation.

- :func:`static_estimation` / :class:`StaticEstimation`: WLS, the χ² and largest-normalised-
  residual tests, the exact detection probability of an injection;
- ``stealth_attack_v0`` (:mod:`fdia_env.stealth.stealth_attack_v0`): the attacker's
  environment (PettingZoo parallel and AEC), with the Gymnasium views
  ``"fdia_env/StealthAttack-v0"`` and ``"fdia_env/StealthDefender-v0"``, registered with the
  others by ``import fdia_env`` (its entry in the table of environments,
  ``fdia_env.registration.ENVS``).

See docs/guide/stealth.md.
"""

from fdia_env.stealth.static import (
    TESTS,
    StaticEstimation,
    check_alpha,
    sidak_threshold,
    static_estimation,
)

GYM_ID = "fdia_env/StealthAttack-v0"
"""Gymnasium id of the attacker's single-agent view; ``make_vec(...,
vectorization_mode="vector_entry_point")`` gives the native numpy vector env
(:class:`fdia_env.stealth.vector.StealthVectorEnv`). Its entry is in the table of environments
(:data:`fdia_env.registration.ENVS`)."""

DEFENDER_GYM_ID = "fdia_env/StealthDefender-v0"
"""Gymnasium id of the threshold defender's view (``defender="threshold"``). It has no native
vector env (the table's ``vector_views``): ``make_vec`` steps copies in ``SyncVectorEnv``."""

__all__ = [
    "DEFENDER_GYM_ID",
    "GYM_ID",
    "TESTS",
    "StaticEstimation",
    "check_alpha",
    "sidak_threshold",
    "static_estimation",
]
