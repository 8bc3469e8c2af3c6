"""Native Gymnasium vector env: B copies of a single-agent view stepped as one computation.

``gymnasium.make_vec("fdia_env/SparseAttack-v0", num_envs=B,
vectorization_mode="vector_entry_point")`` returns :class:`FdiaVectorEnv`. Member ``i`` follows
the single env exactly: reset with ``seed`` gives member ``i`` the seed ``seed + i`` (as
``SyncVectorEnv`` does), expected dynamics are deterministic, and sampled dynamics draw each
member's noise from its own generator in the single env's order. For the 2-state models in
expected dynamics (numpy, and torch on the CPU) the members are nodes of a table of the attack
histories reached (:mod:`fdia_env.envs.history`), computed by the single env's own kernel. On
numpy every member's observations, rewards, Φ and infos equal its single env's bit for bit, in
or out of that table, in both dynamics (see :mod:`fdia_env.envs.engine` for the two grid-scale
cases that match to round-off).

Autoreset follows Gymnasium's rules: ``autoreset_mode=AutoresetMode.NEXT_STEP`` (default, as
``SyncVectorEnv``) resets a finished member on the next ``step`` (its action is ignored, reward 0,
not terminated); ``SAME_STEP`` resets it in the same step and puts the last observation and info
in ``infos["final_obs"]`` and ``infos["final_info"]`` (what stable-baselines3 expects; see
:mod:`fdia_env.vector.sb3`). ``max_episode_steps`` truncates as Gymnasium's ``TimeLimit`` does.

Infos follow Gymnasium's vector convention, key by key as ``SyncVectorEnv`` of the single env
builds them: each key of the single env's info holds a (B, ...) array of the members' values,
paired with a boolean ``_key`` mask (all True: every member reports every key).

A fixed opponent (two-player envs) acts for the whole batch with one ``predict`` call on the
(B, d) observations, except a :class:`~fdia_env.envs.opponents.FixedMix` (the default of the
sensor game's views): it draws from one generator per member, seeded as the single env seeds its
opponent (``seed + i + 1``), so member ``i`` replays the single env seeded ``seed + i``.

``backend="torch", device="cpu" | "cuda"`` runs the same engine and models on torch tensors
(float64) of that device, for every id the table of environments lists with the torch backend
(:func:`fdia_env.registration.torch_ids`): actions must be tensors
on the device; observations (float32), rewards (float64), terminations, truncations, infos and
action masks are tensors there; ``reset(seed=s)`` seeds one ``torch.Generator`` on the device
that every member draws from (sampled dynamics: equal to the numpy backend in distribution, not
draw for draw; expected dynamics: equal member by member). In ``SAME_STEP`` mode
``infos["final_obs"]`` is a (B, d) tensor (rows of the members whose ``_final_obs`` is False are
zeros). A policy opponent's ``predict`` gets and gives numpy (a host round trip); the detection
game's exact expected errors are integrated on the host (see :mod:`fdia_env.detection.step`).
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from fdia_env._validation import check_agent, check_int
from fdia_env.actions import check_vector_actions
from fdia_env.backend import NUMPY, get_backend
from fdia_env.envs.engine import BatchedSimulation
from fdia_env.envs.opponents import FixedMix
from fdia_env.envs.parallel import FdiaParallelEnv, attacker_reward, check_reset_args
from fdia_env.envs.single_agent import Policy, check_no_opponent, check_opponent
from fdia_env.registration import ENVS, torch_ids

# members of one vector env: every member holds (n, n) covariances, its features and, for the
# sparse attack, a (2**M,) action mask; a larger batch is a typo (10**9), not a workload
MAX_NUM_ENVS = 2**20
# on torch (a GPU's memory) the batch may be larger: benchmarks/gpu.py measures up to B = 2**24
MAX_NUM_ENVS_TORCH = 2**24

FORMAT_VECTOR_ENVS: dict[tuple[str, Any], Callable[..., gym.vector.VectorEnv]] = {}
"""(module, ``action``) → that action format's own native vector env: a class, which
:func:`make_vector` builds as it builds :class:`FdiaVectorEnv` (from the module's env, with the
same arguments; :mod:`fdia_env.vector.sequential_game` adds the sensor game's
``"sequential"``), or a maker of its own, called with :func:`make_vector`'s arguments
(:mod:`fdia_env.vector.sequential` adds the sparse attacker's ``"sequential"``)."""


class FdiaVectorEnv(gym.vector.VectorEnv):
    """B environments of one fdia_env single-agent view, as batched numpy or torch.

    Args:
        parallel: A two-player env instance; its scenario, models and episode spec are used.
        num_envs: B (1..``MAX_NUM_ENVS``; on torch 1..``MAX_NUM_ENVS_TORCH``).
        agent: The learning player.
        opponent: Policy of the other player (uniform mix over its actions by default).
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` or ``AutoresetMode.SAME_STEP``.
        max_episode_steps: Truncate each member's episode after this many steps (as
            Gymnasium's ``TimeLimit``: ``truncated`` is True at that step even if the episode
            also terminates there), or None.
        backend: ``"numpy"`` (default) or ``"torch"`` (see the module doc).
        device: torch only: ``"cpu"`` (default), ``"cuda"`` or ``"cuda:<i>"``.

    Raises:
        ValueError: For an unknown backend, a device that is not there (``"cuda"`` without a
            GPU), or ``backend="torch"`` for an env whose models have no torch implementation.
    """

    def __init__(
        self,
        parallel: FdiaParallelEnv,
        num_envs: int,
        agent: str = "attacker",
        opponent: Policy | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        max_episode_steps: int | None = None,
        backend: str = "numpy",
        device: Any = None,
    ) -> None:
        if not isinstance(parallel, FdiaParallelEnv):  # e.g. the sparse attack's "sequential"
            raise TypeError(
                f"parallel must be an FdiaParallelEnv, got {type(parallel).__name__} (the sparse "
                "attack's action='sequential' has its own native vector env, "
                "fdia_env.vector.sequential.SequentialVectorEnv)"
            )
        self.xp = xp = get_backend(backend, device)
        self.num_envs = check_int("num_envs", num_envs, minimum=1, maximum=_max_envs(xp))
        check_agent(agent, parallel.possible_agents)
        mode, self.max_episode_steps = check_episode_options(autoreset_mode, max_episode_steps)
        self.metadata = {"autoreset_mode": mode, "render_modes": [], "backend": backend}
        self.render_mode = None
        self.parallel = parallel
        self.agent = agent
        others = [a for a in parallel.possible_agents if a != agent]
        self.other = others[0] if others else None
        if self.other is not None and opponent is None:
            opponent = FixedMix.uniform(int(parallel.action_space(self.other).n))
        if self.other is not None:
            check_opponent(opponent, parallel.action_space(self.other))
        else:
            check_no_opponent(opponent, parallel.possible_agents)
        if xp is not NUMPY:
            _check_torch_support(parallel)
        self.backend, self.device = xp.name, xp.device
        self.opponent = opponent
        self._mix = isinstance(opponent, FixedMix)  # drawn per member (see the module doc)
        self._opp_rngs: list[np.random.Generator] | None = None
        self.attack, self.defense = parallel.attack, parallel.defense
        self.spec_episode = parallel.spec
        space = parallel.observation_space(agent)
        self._masked = isinstance(space, spaces.Dict)
        self.single_observation_space = space["observation"] if self._masked else space
        self.single_action_space = parallel.action_space(agent)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._dims = {
            a: _box(parallel.observation_space(a)).shape[0] for a in parallel.possible_agents
        }
        self._models = {"attacker": self.attack, "defender": self.defense}
        self.sim: BatchedSimulation | None = None
        self._generator: Any = None  # torch: the device generator every member draws from
        self._prev_done = xp.zeros(self.num_envs, dtype=xp.bool)
        self._all = xp.ones(self.num_envs, dtype=xp.bool)  # the shared all-True `_key` mask
        if xp is NUMPY:
            self._all.setflags(write=False)
        self._det_defaults = self.defense.info_defaults(parallel.sim.sampled)

    @property
    def autoreset_mode(self) -> AutoresetMode:
        """Gymnasium's autoreset mode of this env (also in ``metadata["autoreset_mode"]``)."""
        return self.metadata["autoreset_mode"]

    # --- reset ---------------------------------------------------------------------------------
    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        """Reset every member; an int ``seed`` seeds member i with ``seed + i``.

        Raises:
            ValueError: For a seed that is not a non-negative integer or a list of B of them
                (None entries allowed); ``options`` as in :func:`check_reset_args`.
        """
        B = self.num_envs
        known = self.attack.reset_options
        if self.xp is not NUMPY:
            return self._reset_torch(seed, options)
        if seed is None or (isinstance(seed, int | np.integer) and not isinstance(seed, bool)):
            check_reset_args(seed, options, known)
            seeds = [None] * B if seed is None else [int(seed) + i for i in range(B)]
        elif isinstance(seed, list | tuple):
            if len(seed) != B:
                raise ValueError(f"seed must be an int or a list of {B} seeds, got {len(seed)}")
            for s in seed:
                check_reset_args(s, None)
            check_reset_args(None, options, known)
            seeds = [None if s is None else int(s) for s in seed]
        else:
            raise ValueError(f"seed must be an int, a list of {B} ints or None, got {seed!r}")
        self.attack.check_reset_options(dict(options or {}))
        super().reset(seed=None if seed is None or isinstance(seed, list | tuple) else int(seed))
        # a member without a seed keeps its generator (as a single env's reset(seed=None)
        # does in SyncVectorEnv); only the first reset draws fresh entropy for it
        old = getattr(self, "_rngs", None)
        self._rngs = [
            old[i] if s is None and old is not None else seeding.np_random(s)[0]
            for i, s in enumerate(seeds)
        ]
        if self._mix:  # one opponent generator per member, as each single env has its own
            prev = self._opp_rngs
            self._opp_rngs = [
                prev[i]
                if s is None and prev is not None
                else np.random.default_rng(None if s is None else s + 1)
                for i, s in enumerate(seeds)
            ]
        elif seed is not None and not isinstance(seed, list | tuple):
            if hasattr(self.opponent, "reset"):
                self.opponent.reset(seed=int(seed) + 1)
        if self.sim is None:
            self.sim = BatchedSimulation(self.parallel.system, self.parallel.spec, B)
        self.sim.rngs = self._rngs
        return self._reset_all(options)

    def _reset_torch(self, seed: Any, options: dict | None):
        """``reset`` on torch: an int ``seed`` seeds the device generator."""
        if isinstance(seed, list | tuple):
            raise ValueError(
                "seed must be an int or None for backend='torch' (one torch.Generator on the "
                f"device draws for every member), got a list of {len(seed)}"
            )
        check_reset_args(seed, options, self.attack.reset_options)
        self.attack.check_reset_options(dict(options or {}))
        super().reset(seed=None if seed is None else int(seed))
        if seed is not None or self._generator is None:
            self._generator = self.xp.generator(None if seed is None else int(seed))
        if seed is not None and not self._mix and hasattr(self.opponent, "reset"):
            self.opponent.reset(seed=int(seed) + 1)  # a policy opponent, as on numpy
        if self.sim is None:
            self.sim = BatchedSimulation(
                self.parallel.system, self.parallel.spec, self.num_envs, self.xp
            )
        self.sim.generator = self._generator
        return self._reset_all(options)

    def _reset_all(self, options: dict | None = None):
        """Every member at the window start: the engine, the models, the infos."""
        B, xp = self.num_envs, self.xp
        self.attack.xp = self.defense.xp = xp
        self.sim.reset(None)
        self.attack.batch_reset(B)
        self.defense.batch_reset(B)
        # nature's draws (the sensor game's type), from each member's generator on numpy, the
        # device generator on torch; options force them for this reset only: an autoreset
        # draws them, as SyncVectorEnv's autoreset calls reset() without options
        rngs = self._rngs if xp is NUMPY else self._generator
        self.attack.batch_draw_nature(rngs, None, dict(options or {}))
        self._prev_done = xp.zeros(B, dtype=xp.bool)
        self._det_info = {
            key: xp.full(B, value, dtype=np.dtype(type(value)))
            for key, value in self._det_defaults.items()
        }
        return self._observe(self.agent), self._infos()

    def _reset_members(self, where: np.ndarray) -> None:
        """Reset the members of the (B,) boolean mask ``where``."""
        self.sim.reset(where)
        self.attack.batch_reset(self.num_envs, where)
        self.defense.batch_reset(self.num_envs, where)
        rngs = self._rngs if self.xp is NUMPY else self._generator
        self.attack.batch_draw_nature(rngs, where)
        for key, value in self._det_defaults.items():
            self._det_info[key][where] = value

    # --- step ----------------------------------------------------------------------------------
    def step(self, actions: Any):
        """Step every member (NEXT_STEP: members finished last step are reset instead)."""
        if self.sim is None:
            raise RuntimeError("step() called before reset(): call reset() first")
        B, xp = self.num_envs, self.xp
        resetting = self._prev_done
        # the only check: the models take the checked actions as valid
        actions = {
            self.agent: check_vector_actions(self.single_action_space, actions, B, self.agent, xp)
        }
        if self.other is not None:
            actions[self.other] = self._opponent_actions(~resetting)
            space = self.parallel.action_space(self.other)
            actions[self.other] = check_vector_actions(
                space, actions[self.other], B, self.other, xp
            )
        attacked, sigma = self.attack.batch_apply(actions["attacker"])
        used, leak, present, steady = self.defense.batch_apply(
            actions.get("defender"), attacked, sigma
        )
        if self.other is not None:
            self.attack.batch_observe_opponent(self.defense)
            self.defense.batch_observe_opponent(self.attack)
        phi_prev = self.sim.phi
        phi = self.sim.step(
            used,
            leak,
            present,
            steady,
            active=~resetting,
            detection=self.defense.batch_detection(),
            probability=self.attack.batch_probability(),
        )
        if self._det_defaults:  # the detector's per-member info, for the members that stepped
            for key, values in self.sim.detection_info.items():
                self._det_info[key] = xp.where(resetting, self._det_info[key], values)
        k = self.sim.k
        done = k >= self.spec_episode.horizon
        truncated = xp.zeros(B, dtype=xp.bool)
        if self.parallel.max_cycles is not None:  # the env's own limit (PettingZoo's)
            truncated |= ~done & (k >= self.parallel.max_cycles)
        if self.max_episode_steps is not None:  # Gymnasium's TimeLimit
            truncated |= k >= self.max_episode_steps
        reward = attacker_reward(self.spec_episode.reward_mode, phi, phi_prev, done, xp)
        if self.agent == "defender":
            reward = -reward
        infos: dict[str, Any] = {}
        if self.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP:
            if xp.any(resetting):
                self._reset_members(resetting)
                reward[resetting] = 0.0
                done[resetting] = False
                truncated[resetting] = False
            self._prev_done = done | truncated
            obs = self._observe(self.agent)
        else:  # SAME_STEP: finished members restart now; their last step goes in infos
            obs = self._observe(self.agent)
            ended = done | truncated
            if xp.any(ended):
                if xp is NUMPY:
                    final = np.full(B, None, dtype=object)
                    for i in np.flatnonzero(ended):
                        final[i] = obs[i].copy()
                else:  # torch has no object arrays: a (B, d) tensor, zeros where not ended
                    final = xp.where(ended[:, None], obs, 0.0)
                final_info = _masked(self._infos(), ended, xp)
                infos = {
                    "final_obs": final,
                    "_final_obs": xp.copy(ended),
                    "final_info": final_info,
                    "_final_info": xp.copy(ended),
                }
                self._reset_members(xp.copy(ended))
                obs = self._observe(self.agent)
        infos.update(self._infos())
        return obs, reward, done, truncated, infos

    def _opponent_actions(self, stepping: np.ndarray) -> np.ndarray:
        """The fixed opponent's (B, ...) actions; a FixedMix draws only for ``stepping``."""
        B, xp = self.num_envs, self.xp
        if self._mix and xp is not NUMPY:  # torch: the device generator draws for every member
            mix: FixedMix = self.opponent
            index = xp.searchsorted(mix._cdf, xp.uniform(self._generator, B))
            return xp.minimum(index, mix.n_actions - 1)
        if self._mix:
            mix = self.opponent
            u = np.zeros(B)
            for i in np.flatnonzero(stepping):  # each member's generator, as its single env's
                u[i] = self._opp_rngs[i].random()
            return np.minimum(np.searchsorted(mix._cdf, u, side="right"), mix.n_actions - 1)
        obs = self._observe(self.other)
        if xp is not NUMPY:  # a policy's predict takes and gives numpy (SB3's convention)
            obs = xp.to_numpy(obs)
        action, _ = self.opponent.predict(obs, deterministic=True)
        shape = self.parallel.action_space(self.other).shape or ()
        try:
            if xp is not NUMPY:
                return xp.asarray(np.asarray(action).reshape(B, *shape))
            return np.asarray(action).reshape(B, *shape)
        except ValueError as exc:
            raise ValueError(
                f"opponent.predict must return one {self.other} action per member, shape "
                f"{(B, *shape)}, got shape {np.shape(action)}"
            ) from exc

    # --- observations ----------------------------------------------------------------------------
    def _observe(self, agent: str) -> np.ndarray:
        """(B, d) float32 observations of ``agent``, a transposed view of a (d, B) buffer."""
        rows = self.xp.empty((self._dims[agent], self.num_envs), dtype=self.xp.float32)
        col = self.sim.features(rows)
        rows[col:] = self._models[agent].batch_features().T
        return rows.T

    def _infos(self) -> dict[str, Any]:
        """Gymnasium vector infos: the single env's keys, each with its all-True ``_key``."""
        # phi is a fresh array every step; k is updated in place, so it is copied
        values: dict[str, Any] = {"phi": self.sim.phi, "step": self.xp.copy(self.sim.k)}
        values.update(self.attack.batch_info())
        if self.agent == "attacker":
            values.update(self.attack.batch_private_info())
        for key, array in self._det_info.items():
            values[key] = self.xp.copy(array)
        if self._masked:
            values["action_mask"] = self._models[self.agent].batch_action_mask()
        infos: dict[str, Any] = {}
        for key, value in values.items():
            infos[key] = value
            infos["_" + key] = self._all
        return infos

    def action_masks(self) -> np.ndarray:
        """(B, A) legal actions of the learning player (all legal where unmasked)."""
        xp = self.xp
        mask = self._models[self.agent].batch_action_mask()
        if mask is None:
            n = int(getattr(self.single_action_space, "n", 1))
            return xp.ones((self.num_envs, n), dtype=xp.bool)
        return xp.astype(mask, xp.bool)


def check_episode_options(
    autoreset_mode: AutoresetMode | str, max_episode_steps: int | None
) -> tuple[AutoresetMode, int | None]:
    """A native vector env's ``autoreset_mode`` (NEXT_STEP or SAME_STEP) and episode cap.

    Raises:
        ValueError: Naming ``autoreset_mode`` (unknown, or DISABLED) or ``max_episode_steps``
            (not a positive integer).
    """
    try:
        mode = AutoresetMode(autoreset_mode)
    except ValueError as exc:
        raise ValueError(
            f"autoreset_mode must be one of {[m.value for m in AutoresetMode]}, "
            f"got {autoreset_mode!r}"
        ) from exc
    if mode == AutoresetMode.DISABLED:
        raise ValueError("autoreset_mode must be NEXT_STEP or SAME_STEP, got DISABLED")
    if max_episode_steps is not None:
        max_episode_steps = check_int("max_episode_steps", max_episode_steps, minimum=1)
    return mode, max_episode_steps


def _masked(infos: dict[str, Any], where: Any, xp=NUMPY) -> dict[str, Any]:
    """``infos`` reported by the members ``where`` only (their ``_key`` masks set to it)."""
    out: dict[str, Any] = {}
    for key, value in infos.items():
        if not key.startswith("_"):
            kept = xp.where(where.reshape(-1, *[1] * (value.ndim - 1)), value, 0)
            out[key] = xp.astype(kept, value.dtype)
            out["_" + key] = xp.copy(where)
    return out


def _max_envs(xp) -> int:
    return MAX_NUM_ENVS if xp is NUMPY else MAX_NUM_ENVS_TORCH


def _check_torch_support(parallel: FdiaParallelEnv) -> None:
    """``ValueError`` unless this env's models run on torch (see :func:`torch_ids`)."""
    missing = [
        type(m).__name__
        for m in (parallel.attack, parallel.defense)
        if "torch" not in m.batch_backends
    ]
    if missing:
        raise ValueError(
            f"backend='torch' is not implemented for {parallel.metadata.get('name')} "
            f"({', '.join(missing)} has no torch batch implementation yet); "
            f"backend='torch' supports {', '.join(torch_ids())} (their options included); "
            "use backend='numpy' for the others"
        )


_VECTOR_DEFAULTS = {
    name: param.default
    for name, param in inspect.signature(FdiaVectorEnv.__init__).parameters.items()
    if param.default is not inspect.Parameter.empty
}


def _box(space: spaces.Space) -> spaces.Box:
    return space["observation"] if isinstance(space, spaces.Dict) else space


def split_vector_options(kwargs: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Split :func:`make_vector`'s keywords into the vector env's options and the env's.

    The vector env's options are the keyword parameters of ``FdiaVectorEnv.__init__``
    (``agent``, ``opponent``, ``autoreset_mode``, ``max_episode_steps``, ``backend``,
    ``device``), with its defaults for those not given, so the class's signature is their one
    definition.

    Returns:
        The vector env's options (all of them) and the other keywords (the env's own).
    """
    options = {name: kwargs.get(name, default) for name, default in _VECTOR_DEFAULTS.items()}
    return options, {k: v for k, v in kwargs.items() if k not in _VECTOR_DEFAULTS}


def make_vector(module: str, num_envs: int, **kwargs: Any) -> gym.vector.VectorEnv:
    """Gymnasium ``vector_entry_point``: ``fdia_env.<module>.parallel_env(**kwargs)`` × B.

    As Gymnasium's entry points, it takes every option as a keyword: the vector env's
    (``agent``, ``opponent``, ``autoreset_mode``, ``max_episode_steps``, ``backend``,
    ``device``; see :class:`FdiaVectorEnv` for their meaning, defaults and errors) and the
    env's own (the rest, passed to ``parallel_env``). ``backend`` and ``device`` choose numpy
    (default) or torch on a device; they are checked before the env is built. The sparse
    attacker's ``action="sequential"`` gets
    :class:`fdia_env.vector.sequential.SequentialVectorEnv`, the sensor game's
    :class:`fdia_env.vector.sequential_game.SequentialGameVectorEnv` (through
    :data:`FORMAT_VECTOR_ENVS`).

    Raises:
        ValueError: For a bad vector option (as :class:`FdiaVectorEnv`), a render mode, a
            backend the env's entry in :data:`fdia_env.registration.ENVS` does not list, or an
            action format the native vector env does not run.
    """
    action = kwargs.get("action")
    # only a format name can select a native vector env of its own (anything else, e.g. an
    # array, goes on to the env, whose own check names the parameter)
    fmt = FORMAT_VECTOR_ENVS.get((module, action)) if isinstance(action, str | None) else None
    if fmt is not None and not isinstance(fmt, type):  # a format's maker of its own
        return fmt(module, num_envs, **kwargs)
    options, kwargs = split_vector_options(kwargs)
    backend, device = options["backend"], options["device"]
    xp = get_backend(backend, device)  # an unknown backend or a missing GPU fails first
    if kwargs.get("render_mode") is not None:
        raise ValueError("render_mode is not supported by the native vector env; use SyncVectorEnv")
    kwargs.pop("render_mode", None)
    check_int("num_envs", num_envs, minimum=1, maximum=_max_envs(xp))
    entry = next((e for e in ENVS.values() if e.module == module), None)
    if entry is not None and backend not in entry.backends:
        raise ValueError(
            f"backend={backend!r} is not one of {entry.name}'s backends {list(entry.backends)} "
            "(its entry in fdia_env.registration.ENVS)"
        )
    mod = importlib.import_module(module)
    parallel = mod.parallel_env(**kwargs)
    if fmt is None:
        if not isinstance(parallel, FdiaParallelEnv):  # e.g. the sparse attack's "sequential"
            raise ValueError(
                f"action={kwargs.get('action')!r} is not available in the native vector env (it "
                f"wraps the env as a {type(parallel).__name__}); use gymnasium.make_vec(..., "
                "vectorization_mode='sync') or another action format"
            )
        agent = options["agent"]
        check_agent(agent, parallel.possible_agents)
        if (
            options["opponent"] is None
            and hasattr(mod, "default_opponent")
            and len(parallel.possible_agents) > 1
        ):
            options["opponent"] = mod.default_opponent(parallel, agent)
    # a format's own vector env class checks the env and its options itself
    return (FdiaVectorEnv if fmt is None else fmt)(parallel, num_envs, **options)
