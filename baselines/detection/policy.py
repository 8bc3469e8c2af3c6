"""A detector as the defender of ``detection_game_v0`` (stable-baselines3 ``predict`` signature)."""

from __future__ import annotations

from typing import Any

from baselines.detection.detectors import Detector
from fdia_env.detection_game_v0 import FixedAction


def as_policy(detector: Detector, env: Any) -> FixedAction:
    """The fixed threshold action that makes ``env``'s defender play ``detector``.

    Args:
        detector: OBDD, OBDI, CBD or CSD (:mod:`baselines.detection.detectors`).
        env: A ``detection_game_v0`` parallel env or one of its Gymnasium views, built with the
            detector's statistic and ``on_detect`` (e.g. ``statistic="chi2"`` for CSD,
            ``on_detect="incorporate"`` for OBDI).

    Raises:
        ValueError: When the env's defender uses another statistic or ``on_detect``.

    Example:
        >>> from fdia_env import detection_game_v0
        >>> from baselines.detection import obdd, static_problem
        >>> env = detection_game_v0.parallel_env(scenario="ch3-static", power=240.0)
        >>> as_policy(obdd(static_problem("ch3-static", power=240.0)), env).action.round(4)
        array([0.1189], dtype=float32)
    """
    parallel = getattr(getattr(env, "unwrapped", env), "parallel", env)
    defense = getattr(parallel, "defense", None)
    if not hasattr(defense, "threshold_to_action"):
        raise ValueError("env must be a detection_game_v0 env or one of its Gymnasium views")
    for name in ("statistic", "on_detect"):
        mine, theirs = getattr(detector, name), getattr(defense, name)
        if mine != theirs:
            raise ValueError(
                f"{detector.name} uses {name}={mine!r} but the env's defender uses {theirs!r}; "
                f"build the env with {name}={mine!r}"
            )
    return FixedAction(defense.threshold_to_action(detector.threshold))
