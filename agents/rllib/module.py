"""RLlib's default PPO module, masked: plain ``PPOConfig().environment(name)`` on every env.

RLlib's default PPO RL module encodes a flat ``Box`` observation only; a masked player's
observation is a ``Dict`` of the features and the action mask, and RLlib stops with ``No default
encoder config for obs space=Dict('action_mask' ...)``. :class:`MaskedPPOTorchRLModule` is the
default module with one addition: given a ``Dict`` observation space holding ``"action_mask"``
and ``"observations"`` (RLlib's form, :mod:`agents.rllib.envs`) or ``"observation"``
(PettingZoo's form, as RLlib's ``ParallelPettingZooEnv`` passes it), its networks read the
features and the logits of illegal actions are ``log(0)`` clamped to -3.4e38, so an illegal
action has probability 0. On any other space it is the default module, unchanged.

:func:`register_default_module` (run by :func:`agents.rllib.envs.register_envs`, and in every
env runner that builds one of its envs) makes it the module ``PPOConfig`` builds when the config
names none: an ``rl_module(rl_module_spec=...)`` with a ``module_class`` still wins.
"""

from __future__ import annotations

from typing import Any

from gymnasium import spaces
from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import DefaultPPOTorchRLModule
from ray.rllib.core.columns import Columns
from ray.rllib.utils.torch_utils import FLOAT_MIN

MASK_KEY = "action_mask"
FEATURE_KEYS = ("observations", "observation")  # RLlib's form, PettingZoo's form


def mask_keys(space: Any) -> tuple[str, str] | None:
    """(features key, mask key) of a masked ``Dict`` observation space, else None."""
    if not isinstance(space, spaces.Dict) or MASK_KEY not in space.spaces:
        return None
    for key in FEATURE_KEYS:
        if key in space.spaces and len(space.spaces) == 2:
            return key, MASK_KEY
    return None


class MaskedPPOTorchRLModule(DefaultPPOTorchRLModule):
    """RLlib's default PPO torch module that also reads masked ``Dict`` observations.

    Args:
        observation_space: The player's observation space; a masked ``Dict`` (see
            :func:`mask_keys`) builds the networks on its features.
        **kwargs: As for RLlib's ``DefaultPPOTorchRLModule``.
    """

    def __init__(self, *, observation_space: Any = None, **kwargs: Any) -> None:
        self._keys = mask_keys(observation_space)
        self._space_with_mask = observation_space
        inner = observation_space[self._keys[0]] if self._keys else observation_space
        super().__init__(observation_space=inner, **kwargs)

    def setup(self) -> None:
        """Build the default networks, then show the env's (masked) space again."""
        super().setup()
        if self._keys is not None:
            self.observation_space = self._space_with_mask

    def _split(self, batch: dict[str, Any]) -> tuple[dict[str, Any], Any]:
        obs = batch.get(Columns.OBS)
        if self._keys is None or not isinstance(obs, dict):
            return batch, None
        features, mask = self._keys
        batch = dict(batch)
        batch[Columns.OBS] = obs[features]
        return batch, obs[mask]

    @staticmethod
    def _masked(out: dict[str, Any], mask: Any) -> dict[str, Any]:
        if mask is not None:
            import torch

            out[Columns.ACTION_DIST_INPUTS] = out[Columns.ACTION_DIST_INPUTS] + torch.clamp(
                torch.log(mask.to(out[Columns.ACTION_DIST_INPUTS].dtype)), min=FLOAT_MIN
            )
        return out

    def _forward(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        """Inference and exploration pass, illegal actions' logits masked."""
        batch, mask = self._split(batch)
        return self._masked(super()._forward(batch, **kwargs), mask)

    def _forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        """Train pass, illegal actions' logits masked."""
        batch, mask = self._split(batch)
        return self._masked(super()._forward_train(batch, **kwargs), mask)

    def compute_values(self, batch: dict[str, Any], embeddings: Any = None) -> Any:
        """Value of the features (the mask is not an input of the networks)."""
        batch, _ = self._split(batch)
        return super().compute_values(batch, embeddings)


def register_default_module() -> None:
    """Make :class:`MaskedPPOTorchRLModule` the module of a ``PPOConfig`` that names none.

    Idempotent. A config whose ``rl_module`` spec sets a ``module_class`` keeps it.
    """
    from ray.rllib.algorithms.ppo import PPOConfig

    original = PPOConfig.get_default_rl_module_spec
    if getattr(original, "masked_default", False):
        return

    def get_default_rl_module_spec(self: Any) -> Any:
        spec = original(self)
        if getattr(spec, "module_class", None) is DefaultPPOTorchRLModule:
            spec.module_class = MaskedPPOTorchRLModule
        return spec

    get_default_rl_module_spec.masked_default = True  # type: ignore[attr-defined]
    get_default_rl_module_spec.__doc__ = original.__doc__
    PPOConfig.get_default_rl_module_spec = get_default_rl_module_spec
