"""What the two stealth native vector envs share: constructor, seeding, episode end, autoreset.

:class:`StealthVectorBase` is the base of :class:`~fdia_env.stealth.vector.StealthVectorEnv`
and :class:`~fdia_env.stealth.dynamic_vector.StealthDynamicVectorEnv`; :func:`vector_options`
reads the options of their ``vector_entry_point`` that are not the env's own.

Autoreset follows Gymnasium's rules, as the Kalman-filter native vector env's:
``autoreset_mode=AutoresetMode.NEXT_STEP`` (the default) resets a finished member on the next
``step`` (its action is ignored, reward 0, not terminated); ``SAME_STEP`` resets it in the same
step: the step returns its fresh observation and reset info, and puts the last observation and
info in ``infos["final_obs"]`` and ``infos["final_info"]`` (masks ``_final_obs`` and
``_final_info``). On numpy ``final_obs`` is an object array (None where a member did not end);
on torch it is a (B, d) tensor, zeros where a member did not end.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from fdia_env._validation import check_int
from fdia_env.backend import NUMPY, Backend, get_backend


class StealthVectorBase(VectorEnv):
    """B copies of a stealth env's attacker view, stepped as one batch.

    A subclass names its single env (``env_cls``) and largest batch (``max_num_envs``), builds
    its batch state in :meth:`_init_state`, called once the single env and the batched spaces
    are there, and starts members afresh in :meth:`_restart` (every member at :meth:`reset`).

    Args:
        num_envs: B, 1..``max_num_envs``.
        backend: ``"numpy"`` (default) or ``"torch"``.
        device: numpy: None or ``"cpu"``; torch: a ``torch.device`` or its string.
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (default) or ``SAME_STEP`` (see the module
            docstring).
        **kwargs: Options of the single env's ``parallel_env`` (no ``render_mode``).
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP}  # noqa: RUF012
    xp: Backend = NUMPY
    env_cls: type
    max_num_envs: int

    def __init__(
        self,
        num_envs: int,
        backend: str = "numpy",
        device: Any = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        **kwargs: Any,
    ) -> None:
        self.metadata = {"autoreset_mode": check_autoreset_mode(autoreset_mode)}
        self.xp = get_backend(backend, device)
        self.backend, self.device = self.xp.name, self.xp.device
        if kwargs.get("render_mode") is not None:
            raise ValueError("render_mode is not supported by the native vector env")
        kwargs.pop("render_mode", None)
        self.num_envs = check_int("num_envs", num_envs, minimum=1, maximum=self.max_num_envs)
        self.env = self.env_cls(**kwargs)
        self.single_action_space = self.env.action_space("attacker")
        self.single_observation_space = self.env.observation_space("attacker")
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._rng = self._generator(None)
        self._needs_reset = self.xp.zeros(self.num_envs, dtype=np.bool_)  # NEXT_STEP's
        self._init_state()

    def _init_state(self) -> None:
        """Build the batch state (the subclass's)."""
        raise NotImplementedError

    def _generator(self, seed: int | None) -> Any:
        """The batch's generator: numpy's, or a ``torch.Generator`` of the device."""
        return np.random.default_rng(seed) if self.xp is NUMPY else self.xp.generator(seed)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[Any, dict]:
        """Reset every member; ``seed`` seeds the noise of the whole batch."""
        self._seed(seed)
        self._needs_reset[:] = False
        return self._restart(self.xp.ones(self.num_envs, dtype=np.bool_))

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

    def _all_members(self, info: dict[str, Any]) -> dict[str, Any]:
        """``info`` with Gymnasium's all-true mask ``_key`` for each of its keys."""
        mask = self.xp.ones(self.num_envs, dtype=np.bool_)
        info.update({f"_{k}": mask for k in list(info)})
        return info

    @property
    def autoreset_mode(self) -> AutoresetMode:
        """Gymnasium's autoreset mode of this env (also in ``metadata["autoreset_mode"]``)."""
        return self.metadata["autoreset_mode"]

    def _restart(self, members: Any) -> tuple[Any, dict[str, Any]]:
        """Start ``members`` (bool (B,)) afresh; the batch's reset observation and reset info.

        Only the rows of ``members`` of what it returns are used.
        """
        raise NotImplementedError

    def _episode_ends(self, k: Any, live: Any, detected: Any) -> tuple[Any, Any]:
        """(B,) terminated and truncated after a step, as the single env's ``_finish_step``.

        A ``live`` member (not resetting in this step) terminates at ``k >= horizon`` or, with
        ``on_detect="end"``, when ``detected``; one that did not is truncated at ``max_cycles``.
        """
        env = self.env
        ends = k >= env.horizon
        if env.on_detect == "end":
            ends = ends | detected
        terminated = live & ends
        if env.max_cycles is None:
            truncated = self.xp.zeros(self.num_envs, dtype=np.bool_)
        else:
            truncated = live & ~terminated & (k >= env.max_cycles)
        return terminated, truncated

    def _autoreset(self, obs: Any, infos: dict[str, Any], ended: Any) -> tuple[Any, dict]:
        """The step's ``(obs, infos)`` after the finishing of ``ended`` members.

        ``NEXT_STEP``: unchanged; the ``ended`` members reset on the next step. ``SAME_STEP``:
        the ``ended`` members restart now; their rows of ``obs`` and of each info become the
        reset ones, and the step's go in ``final_obs`` / ``final_info`` (see the module
        docstring).
        """
        xp = self.xp
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._needs_reset = ended
            return obs, infos
        if not xp.any(ended):
            return obs, infos
        if xp is NUMPY:
            final: Any = np.full(self.num_envs, None, dtype=object)
            for i in np.flatnonzero(ended):
                final[i] = obs[i].copy()
        else:  # torch has no object arrays: a (B, d) tensor, zeros where not ended
            final = xp.where(ended[:, None], obs, 0.0)
        final_info: dict[str, Any] = {}
        for key, value in infos.items():
            if not key.startswith("_"):
                final_info[key] = xp.astype(xp.where(ended, value, 0), value.dtype)
                final_info["_" + key] = xp.copy(ended)
        fresh_obs, fresh = self._restart(xp.copy(ended))
        out = {
            key: value if key.startswith("_") else xp.where(ended, fresh[key], value)
            for key, value in infos.items()
        }
        out.update(
            final_obs=final,
            _final_obs=xp.copy(ended),
            final_info=final_info,
            _final_info=xp.copy(ended),
        )
        return xp.where(ended[:, None], fresh_obs, obs), out


def check_autoreset_mode(autoreset_mode: Any) -> AutoresetMode:
    """``autoreset_mode`` as an :class:`~gymnasium.vector.AutoresetMode` (NEXT_STEP or SAME_STEP).

    Raises:
        ValueError: Naming ``autoreset_mode`` for an unknown mode or ``DISABLED``.
    """
    try:
        mode = AutoresetMode(autoreset_mode)
    except ValueError:
        mode = None
    if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
        raise ValueError(
            f"autoreset_mode must be AutoresetMode.NEXT_STEP or SAME_STEP (or "
            f"'NextStep' / 'SameStep'), got {autoreset_mode!r}"
        )
    return mode


def entry_point(env_cls: type[StealthVectorBase], label: str) -> Callable[..., Any]:
    """Gymnasium's ``vector_entry_point`` for ``env_cls``: ``make_vector(num_envs, **kwargs)``.

    Args:
        env_cls: The native vector env class (its constructor takes ``num_envs``, ``backend``,
            ``device``, ``autoreset_mode`` and the single env's keyword arguments).
        label: The env as error messages name it (e.g. ``"stealth env"``).

    Returns:
        The entry point; it raises ``ValueError`` for an unknown backend, a device it cannot
        use, the defender's view, or a bad option.
    """

    def make_vector(num_envs: int, **kwargs: Any) -> StealthVectorBase:
        backend, device, autoreset = vector_options(kwargs, label)
        return env_cls(num_envs, backend=backend, device=device, autoreset_mode=autoreset, **kwargs)

    make_vector.__doc__ = (
        f"Gymnasium ``vector_entry_point`` of the {label}: ``{env_cls.__name__}`` × num_envs.\n\n"
        "Raises:\n    ValueError: For an unknown backend, a device it cannot use, the "
        "defender's view, or a bad option.\n"
    )
    return make_vector


def vector_options(kwargs: dict, label: str) -> tuple[str, Any, AutoresetMode]:
    """Pop the entry point's own options from ``kwargs``; ``(backend, device, autoreset_mode)``.

    Raises:
        ValueError: For the defender's view (the native vector env plays the attacker alone) or
            an autoreset mode other than ``NEXT_STEP`` and ``SAME_STEP``; ``label`` names the
            env.
    """
    backend, device = kwargs.pop("backend", "numpy"), kwargs.pop("device", None)
    agent = kwargs.pop("agent", "attacker")
    kwargs.pop("module", None)
    if not (isinstance(agent, str) and agent == "attacker") or kwargs.get("defender") is not None:
        raise ValueError(
            f"the {label}'s native vector env plays the attacker alone (agent='attacker', "
            f"defender=None), got agent={agent!r}, defender={kwargs.get('defender')!r}; use "
            "vectorization_mode='sync' for the defender's view"
        )
    autoreset = check_autoreset_mode(kwargs.pop("autoreset_mode", AutoresetMode.NEXT_STEP))
    return backend, device, autoreset
