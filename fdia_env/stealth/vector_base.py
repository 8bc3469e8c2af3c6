"""What the two stealth native vector envs share: the constructor, seeding, the entry options.

:class:`StealthVectorBase` is the base of :class:`~fdia_env.stealth.vector.StealthVectorEnv`
and :class:`~fdia_env.stealth.dynamic_vector.StealthDynamicVectorEnv`; :func:`vector_options`
reads the options of their ``vector_entry_point`` that are not the env's own.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from fdia_env._validation import check_int
from fdia_env.backend import NUMPY, Backend, get_backend


class StealthVectorBase(VectorEnv):
    """B copies of a stealth env's attacker view, stepped as one batch.

    A subclass calls :meth:`_init_batch` first in its constructor, then builds its batch state.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP}  # noqa: RUF012
    xp: Backend = NUMPY

    def _init_batch(
        self, num_envs: int, env_cls: type, maximum: int, kwargs: dict, backend: str, device: Any
    ) -> None:
        """Resolve the backend, check ``num_envs``, build the single env and the batched spaces."""
        self.xp = get_backend(backend, device)
        self.backend, self.device = self.xp.name, self.xp.device
        if kwargs.get("render_mode") is not None:
            raise ValueError("render_mode is not supported by the native vector env")
        kwargs.pop("render_mode", None)
        self.num_envs = check_int("num_envs", num_envs, minimum=1, maximum=maximum)
        self.env = env_cls(**kwargs)
        self.single_action_space = self.env.action_space("attacker")
        self.single_observation_space = self.env.observation_space("attacker")
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._rng = self._generator(None)

    def _generator(self, seed: int | None) -> Any:
        """The batch's generator: numpy's, or a ``torch.Generator`` of the device."""
        return np.random.default_rng(seed) if self.xp is NUMPY else self.xp.generator(seed)

    def _seed(self, seed: Any) -> None:
        """Reseed the batch's noise when ``seed`` is given (a non-negative int: one generator).

        Raises:
            ValueError: Naming ``seed`` for anything but None or a non-negative int.
        """
        if seed is None:
            return
        if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
            raise ValueError(
                f"seed must be a non-negative int or None (it seeds the batch's one "
                f"generator), got {seed!r}"
            )
        self._rng = self._generator(int(seed))


def vector_options(kwargs: dict, label: str) -> tuple[str, Any]:
    """Pop the entry point's own options from ``kwargs``; ``(backend, device)``.

    Raises:
        ValueError: For the defender's view (the native vector env plays the attacker alone) or
            an autoreset mode other than ``NEXT_STEP``; ``label`` names the env.
    """
    backend, device = kwargs.pop("backend", "numpy"), kwargs.pop("device", None)
    agent = kwargs.pop("agent", "attacker")
    kwargs.pop("module", None)
    if agent != "attacker" or kwargs.get("defender") is not None:
        raise ValueError(
            f"the {label}'s native vector env plays the attacker alone (defender=None); use "
            "vectorization_mode='sync' for the defender's view"
        )
    autoreset = kwargs.pop("autoreset_mode", AutoresetMode.NEXT_STEP)
    if autoreset not in (AutoresetMode.NEXT_STEP, "next_step", "NextStep"):
        raise ValueError(f"autoreset_mode must be NEXT_STEP here, got {autoreset!r}")
    return backend, device
