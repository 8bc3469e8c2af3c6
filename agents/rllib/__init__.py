"""Ray RLlib (new API stack) and Ray Tune on fdia_env: scale-out training and sweeps.

Nothing here imports ray until it is used, so ``import agents`` never needs it; install it with
the ``fdia-env[rllib]`` extra (``pip install -e ".[rllib]"``).

- :mod:`agents.rllib.envs`: RLlib env names for every module (multi-agent) and every Gymnasium
  view (single-agent), with masked players' observations as ``{"observations", "action_mask"}``;
- :mod:`agents.rllib.module`: RLlib's default PPO module, masked, registered by
  :func:`~agents.rllib.envs.register_envs` so that a plain ``PPOConfig().environment(name)``
  runs on every env;
- :mod:`agents.rllib.config`: :func:`~agents.rllib.config.ppo_config`, the PPO config with the
  settings these one-step and few-step episodes need (see its docstring for the figures);
- :mod:`agents.rllib.train`: ``train.py attacker|defender|game --backend rllib``: training,
  per-agent returns, zero-step sampling check, scoring by :func:`agents.evaluate.evaluate`;
- :mod:`agents.rllib.state`: what ``--resume`` reads: RL-module weights, optimizer state and
  counters as tensors (``torch.load(weights_only=True)``) and JSON, never a pickle;
- :mod:`agents.rllib.sweep`: ``train.py sweep``: a Ray Tune sweep over seeds, scenarios and
  hyperparameters, one results table.
"""

from __future__ import annotations

import importlib.util

EXTRA = "fdia-env[rllib]"


class MissingExtraError(ImportError):
    """Ray RLlib is not installed (``pip install -e ".[rllib]"``)."""


class ZeroStepsSampled(RuntimeError):
    """An RLlib iteration sampled no env step (sample timeout, or env runners that failed)."""


def require_ray() -> None:
    """Raise unless ``ray[rllib]`` can be imported.

    Raises:
        MissingExtraError: (an ImportError) naming the ``fdia-env[rllib]`` extra.
    """
    try:
        found = importlib.util.find_spec("ray.rllib") is not None
    except ModuleNotFoundError:  # no ray at all
        found = False
    if not found:
        raise MissingExtraError(
            "--backend rllib and train.py sweep need Ray RLlib, which is not installed: "
            f'pip install -e ".[rllib]" (the {EXTRA} extra: ray[rllib]>=2.60)'
        )
