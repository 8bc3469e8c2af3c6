"""PPO in one file on one torch device: env, rollout buffer and policy never leave it.

In the spirit of CleanRL's ``ppo.py``: the torch backend of the vector envs
(``gymnasium.make_vec(id, num_envs=B, vectorization_mode="vector_entry_point",
backend="torch", device=...)``) steps B members as tensors on the device, the rollout buffer is a
set of (T, B, ...) tensors there, and the actor-critic acts and learns there; nothing crosses to
the host during a rollout except what the env itself needs (its few Python-level checks).

- Discrete actions with action masks (the sparse attacker): the logits of illegal actions are set
  to the dtype's minimum before sampling, so an illegal action has probability 0 exactly; the
  log-probabilities and the entropy are one fused masked log-softmax with a closed-form backward
  (:func:`agents.torch_ops.masked_categorical`), no distribution objects.
- Box actions (the covariance attacker, the detection defender): a Gaussian policy in the
  normalised space [-1, 1]^k (state-independent log std), clipped to it and mapped affinely to the
  env's bounds; the log-probability is of the unclipped draw (as CleanRL).
- Speed: one pass of the actor per rollout step (the draw and its log-probability), rollouts
  under ``torch.no_grad``, preallocated (T, B, ...) buffers, host syncs only to ask whether a
  member was truncated (each step) and three times per iteration (all actions legal, the
  episodes ended, the finite check), Adam's ``foreach`` step, tanh on the CPU from NumPy
  (:class:`agents.torch_ops.Tanh`). Threads are the caller's: ``train.py`` runs one torch thread
  (``--torch-threads``), the fastest for these 64-wide networks.
- GAE(λ), the clipped surrogate, minibatch epochs, advantage normalisation, gradient clipping,
  optional linear learning-rate decay; running normalisation of observations and of rewards (by
  the running std of the return), both kept in the policy (saved with its weights).
- Autoreset: the env runs in ``SAME_STEP`` mode, so every transition is a real one; a truncated
  (not terminated) member is bootstrapped with the value of its ``final_obs``.
- Seeded: ``torch.manual_seed(seed)`` before the networks are built (same initial weights on any
  device), one ``torch.Generator`` on the device for sampling and minibatches, ``env.reset(seed)``.

:func:`train_torch_ppo` returns a :class:`TorchPPOResult` whose ``policy`` has SB3's
``predict(obs, deterministic=True, action_masks=None)`` on numpy, so
:func:`agents.evaluate.evaluate` scores it like any other policy. :func:`save_policy` /
:func:`load_policy` write and read it in the tensor-only format of :mod:`agents.checkpoint`
(``torch.load(weights_only=True)``, a SHA-256 in the JSON; nothing is unpickled).
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from torch import nn

from agents.checkpoint import (
    MAX_COUNT,
    check_count,
    check_seconds,
    inside,
    load_tensors,
    read_json,
    save_pair,
    tensor_file,
)
from agents.options import check_int, check_real
from agents.torch_ops import (
    Tanh,
    categorical_log_prob,
    gumbel_max,
    mask_logits,
    masked_categorical,
    normal_entropy,
    normal_log_prob,
)

ALGO = "torch-ppo"
FORMAT = "fdia_env-torch-ppo-v1"
MAX_NUM_ENVS = 2**24


@dataclass(frozen=True)
class TorchPPOConfig:
    """Hyperparameters of :func:`train_torch_ppo` (CleanRL's names where they exist).

    Attributes:
        total_timesteps: Env steps to train for (rounded up to whole iterations of
            ``num_envs × num_steps``).
        num_envs: Members of the torch vector env, B.
        num_steps: Steps of each member per rollout, T (one iteration = B·T env steps).
        learning_rate: Adam step size (at the start, with ``anneal_lr``).
        anneal_lr: Decay the learning rate linearly to 0 over the iterations.
        gamma: Discount factor.
        gae_lambda: GAE λ.
        num_minibatches: Minibatches per epoch (each B·T / num_minibatches transitions).
        update_epochs: Passes over the rollout per iteration.
        clip_coef: PPO clipping range.
        ent_coef: Entropy bonus.
        vf_coef: Weight of the value loss.
        max_grad_norm: Gradient-norm clip.
        norm_adv: Normalise advantages per minibatch.
        norm_obs: Running normalisation of observations (kept in the policy).
        norm_reward: Scale rewards by the running std of the return.
        hidden: Hidden layer sizes of the actor and of the critic (tanh).
        init_log_std: Initial log std of the Gaussian policy (Box actions, normalised space).
        stop_prob: Discrete actions: initial probability of action 0 (the sequential format's
            stop) when every action is legal, through the actor's output bias (None: uniform).
    """

    total_timesteps: int = 1_000_000
    num_envs: int = 4096
    num_steps: int = 12
    learning_rate: float = 3e-3
    anneal_lr: bool = True
    gamma: float = 1.0
    gae_lambda: float = 0.95
    num_minibatches: int = 4
    update_epochs: int = 4
    clip_coef: float = 0.2
    ent_coef: float = 0.01
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    norm_adv: bool = True
    norm_obs: bool = True
    norm_reward: bool = True
    hidden: tuple[int, ...] = (64, 64)
    init_log_std: float = -0.5
    stop_prob: float | None = None

    def __post_init__(self) -> None:
        check_int("total_timesteps", self.total_timesteps, 1)
        if self.stop_prob is not None:
            check_real("stop_prob", self.stop_prob, lambda v: 0 < v < 1, "in (0, 1)")
        check_int("num_envs", self.num_envs, 1, MAX_NUM_ENVS)
        check_int("num_steps", self.num_steps, 1)
        check_int("num_minibatches", self.num_minibatches, 1)
        check_int("update_epochs", self.update_epochs, 1)
        if self.num_minibatches > self.num_envs * self.num_steps:
            raise ValueError(
                f"num_minibatches must be <= num_envs × num_steps = "
                f"{self.num_envs * self.num_steps}, got {self.num_minibatches}"
            )
        check_real("learning_rate", self.learning_rate, lambda v: v > 0, "> 0")
        check_real("gamma", self.gamma, lambda v: 0 < v <= 1, "in (0, 1]")
        check_real("gae_lambda", self.gae_lambda, lambda v: 0 <= v <= 1, "in [0, 1]")
        check_real("clip_coef", self.clip_coef, lambda v: v > 0, "> 0")
        check_real("ent_coef", self.ent_coef, lambda v: v >= 0, ">= 0")
        check_real("vf_coef", self.vf_coef, lambda v: v >= 0, ">= 0")
        check_real("max_grad_norm", self.max_grad_norm, lambda v: v > 0, "> 0")
        check_real("init_log_std", self.init_log_std, lambda v: True, "finite")
        for name in ("anneal_lr", "norm_adv", "norm_obs", "norm_reward"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"{name} must be True or False, got {getattr(self, name)!r}")
        if not isinstance(self.hidden, tuple | list) or not self.hidden:
            raise TypeError(
                f"hidden must be a non-empty sequence of layer sizes, got {self.hidden!r}"
            )
        for size in self.hidden:
            check_int("hidden (each layer size)", size, 1)

    @classmethod
    def from_hyperparameters(
        cls, hp: dict[str, Any], total_timesteps: int, num_envs: int
    ) -> TorchPPOConfig:
        """The config of resolved ``train.py`` hyperparameters (``agents.config`` names).

        Raises:
            ValueError: For a value the config rejects (naming it).
        """
        return cls(
            total_timesteps=total_timesteps,
            num_envs=num_envs,
            num_steps=hp["n_steps"],
            learning_rate=hp["learning_rate"],
            anneal_lr=hp["lr_schedule"] == "linear",
            gamma=hp["gamma"],
            gae_lambda=hp["gae_lambda"],
            update_epochs=hp["n_epochs"],
            clip_coef=hp["clip_range"],
            ent_coef=hp["ent_coef"],
            hidden=tuple(hp["net_arch"]),
            num_minibatches=min(4, num_envs * hp["n_steps"]),
            stop_prob=hp.get("stop_prob"),
            norm_obs=hp.get("norm_obs", True),
        )

    @property
    def batch_size(self) -> int:
        """Transitions per iteration, B·T."""
        return self.num_envs * self.num_steps

    @property
    def iterations(self) -> int:
        """Iterations: ``ceil(total_timesteps / (B·T))``."""
        return -(-self.total_timesteps // self.batch_size)


# ---------------------------------------------------------------------------- the policy


def _layer(n_in: int, n_out: int, std: float) -> nn.Linear:
    layer = nn.Linear(n_in, n_out)
    nn.init.orthogonal_(layer.weight, std)
    nn.init.constant_(layer.bias, 0.0)
    return layer


def _mlp(n_in: int, hidden: tuple[int, ...], n_out: int, out_std: float) -> nn.Sequential:
    layers: list[nn.Module] = []
    for size in hidden:
        layers += [_layer(n_in, size, math.sqrt(2)), Tanh()]
        n_in = size
    return nn.Sequential(*layers, _layer(n_in, n_out, out_std))


@dataclass(frozen=True)
class PolicySpec:
    """What builds an :class:`ActorCritic` (saved in the checkpoint's JSON).

    Attributes:
        obs_dim: Observation length d.
        kind: ``"discrete"`` (``Discrete(n)``) or ``"box"`` (``Box`` of ``n`` dimensions).
        n: Actions (discrete) or action dimensions (box).
        hidden: Hidden layer sizes.
        low: Box lower bounds (empty for discrete).
        high: Box upper bounds (empty for discrete).
        init_log_std: Initial log std (box).
    """

    obs_dim: int
    kind: str
    n: int
    hidden: tuple[int, ...] = (64, 64)
    low: tuple[float, ...] = ()
    high: tuple[float, ...] = ()
    init_log_std: float = -0.5

    def __post_init__(self) -> None:
        check_int("obs_dim", self.obs_dim, 1)
        check_int("n", self.n, 1)
        if self.kind not in ("discrete", "box"):
            raise ValueError(f"kind must be 'discrete' or 'box', got {self.kind!r}")
        if self.kind == "box":
            if len(self.low) != self.n or len(self.high) != self.n:
                raise ValueError(f"low and high must have {self.n} entries each")
            if not all(math.isfinite(lo) and math.isfinite(hi) and lo < hi
                       for lo, hi in zip(self.low, self.high, strict=True)):  # fmt: skip
                raise ValueError("a Box action space needs finite bounds with low < high")

    @classmethod
    def of(cls, obs_space: spaces.Space, action_space: spaces.Space, **kwargs: Any) -> PolicySpec:
        """The spec for a (single-member) observation space and action space.

        Raises:
            ValueError: For an action space other than ``Discrete`` or a bounded ``Box``.
        """
        obs_dim = int(np.prod(obs_space.shape))
        if isinstance(action_space, spaces.Discrete):
            return cls(obs_dim, "discrete", int(action_space.n), **kwargs)
        if isinstance(action_space, spaces.Box) and len(action_space.shape) == 1:
            low = tuple(float(v) for v in action_space.low)
            high = tuple(float(v) for v in action_space.high)
            return cls(obs_dim, "box", int(action_space.shape[0]), low=low, high=high, **kwargs)
        raise ValueError(
            f"torch-ppo supports Discrete and 1-D bounded Box action spaces, got {action_space}"
        )


class ActorCritic(nn.Module):
    """Separate actor and critic MLPs, with the running observation statistics as buffers."""

    def __init__(self, spec: PolicySpec) -> None:
        super().__init__()
        self.spec = spec
        self.critic = _mlp(spec.obs_dim, tuple(spec.hidden), 1, 1.0)
        self.actor = _mlp(spec.obs_dim, tuple(spec.hidden), spec.n, 0.01)
        self.box = spec.kind == "box"
        if self.box:
            self.log_std = nn.Parameter(torch.full((spec.n,), float(spec.init_log_std)))
            self.register_buffer("low", torch.tensor(spec.low, dtype=torch.float32))
            self.register_buffer("high", torch.tensor(spec.high, dtype=torch.float32))
        self.register_buffer("obs_mean", torch.zeros(spec.obs_dim, dtype=torch.float64))
        self.register_buffer("obs_var", torch.ones(spec.obs_dim, dtype=torch.float64))
        self.register_buffer("obs_count", torch.tensor(0.0, dtype=torch.float64))

    # --- observations
    def update_obs_stats(self, obs: torch.Tensor) -> None:
        """Fold a (N, d) batch into the running mean and variance (Chan et al.)."""
        x = obs.reshape(-1, self.spec.obs_dim).double()
        n = x.shape[0]
        mean, var = x.mean(0), x.var(0, unbiased=False)
        total = self.obs_count + n
        delta = mean - self.obs_mean
        m2 = self.obs_var * self.obs_count + var * n + delta**2 * self.obs_count * n / total
        self.obs_mean.copy_(self.obs_mean + delta * n / total)
        self.obs_var.copy_(m2 / total)
        self.obs_count.copy_(total)

    def normalize(self, obs: torch.Tensor) -> torch.Tensor:
        """Observations scaled by the running statistics, clipped to ±10 (float32).

        Without statistics (``norm_obs=False``: mean 0, variance 1) the raw values, clipped.
        """
        z = (obs.double() - self.obs_mean) / torch.sqrt(self.obs_var + 1e-8)
        return z.clamp(-10.0, 10.0).float()

    # --- heads
    def value(self, x: torch.Tensor) -> torch.Tensor:
        """V(x), shape (N,)."""
        return self.critic(x).squeeze(-1)

    def distribution(self, x: torch.Tensor, mask: torch.Tensor | None = None):
        """(logits masked, None) for discrete actions; (mean, std) for Box actions."""
        out = self.actor(x)
        if self.box:
            return out, self.log_std.exp().expand_as(out)
        return mask_logits(out, mask), None

    def log_prob_entropy(
        self, x: torch.Tensor, action: torch.Tensor, mask: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The log-probability log π(action | x) and the entropy of π(· | x), each (N,).

        Discrete: :func:`agents.torch_ops.masked_categorical` (one fused masked
        log-softmax); Box: the Gaussian's, as ``torch.distributions.Normal`` computes them.
        """
        out = self.actor(x)
        if self.box:
            std = self.log_std.exp().expand_as(out)  # a NaN mean passes: Diverged reports it
            return normal_log_prob(out, std, action), normal_entropy(std)
        return masked_categorical(out, action, mask)

    def act(
        self, x: torch.Tensor, mask: torch.Tensor | None, generator: torch.Generator | None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """A rollout step's draw and its log-probability, from one pass of the actor."""
        a, b = self.distribution(x, mask)
        if self.box:
            noise = torch.randn(a.shape, generator=generator, device=a.device, dtype=a.dtype)
            action = a + b * noise
            return action, normal_log_prob(a, b, action)
        action = gumbel_max(a, generator)
        return action, categorical_log_prob(a, action)

    def sample(
        self,
        x: torch.Tensor,
        mask: torch.Tensor | None,
        generator: torch.Generator | None,
        deterministic: bool = False,
    ) -> torch.Tensor:
        """An action per row: argmax / mean when ``deterministic``, else a draw."""
        a, b = self.distribution(x, mask)
        if self.box:
            if deterministic:
                return a
            noise = torch.randn(a.shape, generator=generator, device=a.device, dtype=a.dtype)
            return a + b * noise
        if deterministic:
            return a.argmax(-1)
        return gumbel_max(a, generator)

    def to_env(self, action: torch.Tensor) -> torch.Tensor:
        """The env's action: discrete as is; Box clipped to [-1, 1] and mapped to its bounds."""
        if not self.box:
            return action
        unit = action.clamp(-1.0, 1.0)
        return self.low + (unit + 1.0) * 0.5 * (self.high - self.low)


class TorchPolicy:
    """A trained :class:`ActorCritic` behind SB3's ``predict`` (numpy in, numpy out).

    Args:
        model: The actor-critic (its device is where ``predict`` computes).
        seed: Seed of the generator of ``deterministic=False`` draws.
    """

    def __init__(self, model: ActorCritic, seed: int = 0) -> None:
        self.model = model.eval()
        self.seed = int(seed)
        self.device = next(model.parameters()).device
        self.generator = torch.Generator(device=self.device).manual_seed(self.seed)

    def snapshot(self) -> TorchPolicy:
        """A policy on a copy of the weights and statistics (later training leaves it as is)."""
        return TorchPolicy(copy.deepcopy(self.model), self.seed)

    @property
    def spec(self) -> PolicySpec:
        """The network's :class:`PolicySpec`."""
        return self.model.spec

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
        action_masks: Any = None,
    ) -> tuple[np.ndarray, None]:
        """Actions for (d,) or (N, d) numpy observations, as SB3's ``predict``.

        Args:
            observation: One observation (d,) or a batch (N, d).
            state: Ignored (no recurrent state).
            episode_start: Ignored.
            deterministic: Greedy action (argmax of the masked logits / the Gaussian mean).
            action_masks: (A,) or (N, A) booleans of the legal actions (discrete), or None.

        Returns:
            ``(actions, None)``: int64 (), (N,) for discrete; float32 (k,), (N, k) for Box, in
            the env's bounds.

        Raises:
            ValueError: For an observation of the wrong length, or masks of the wrong shape.
        """
        obs = np.asarray(observation, dtype=np.float32)
        d = self.spec.obs_dim
        single = obs.ndim == 1
        if obs.shape[-1:] != (d,) or obs.ndim > 2:
            raise ValueError(f"observation must have shape ({d},) or (N, {d}), got {obs.shape}")
        x = torch.as_tensor(obs.reshape(-1, d), device=self.device)
        mask = None
        if action_masks is not None and self.spec.kind == "discrete":
            m = np.asarray(action_masks, dtype=bool).reshape(-1, self.spec.n)
            if m.shape[0] != x.shape[0]:
                raise ValueError(
                    f"action_masks must have shape ({self.spec.n},) or ({x.shape[0]}, "
                    f"{self.spec.n}), got {np.shape(action_masks)}"
                )
            mask = torch.as_tensor(m, device=self.device)
        with torch.no_grad():
            action = self.model.sample(self.model.normalize(x), mask, self.generator, deterministic)
            action = self.model.to_env(action)
        out = action.cpu().numpy()
        out = out.astype(np.int64) if self.spec.kind == "discrete" else out.astype(np.float32)
        return (out[0] if single else out), None


# ---------------------------------------------------------------------------- training


@dataclass
class TorchPPOResult:
    """What :func:`train_torch_ppo` returns.

    Attributes:
        policy: The trained policy (``predict`` on numpy, for :func:`agents.evaluate.evaluate`).
        timesteps: Env steps taken (whole iterations).
        train_seconds: Wall time of the training loop (env steps and updates).
        history: One record per iteration: ``iteration``, ``timesteps``, ``seconds``,
            ``episodes`` ended in it and their ``mean_return`` (NaN when none ended),
            ``learning_rate``.
        interrupted: True when ``stop()`` ended training early.
    """

    policy: TorchPolicy
    timesteps: int
    train_seconds: float
    history: list[dict[str, float]] = field(default_factory=list)
    interrupted: bool = False

    @property
    def steps_per_second(self) -> float:
        """End-to-end env steps per second (rollouts and updates)."""
        return self.timesteps / self.train_seconds if self.train_seconds > 0 else math.nan


@dataclass
class TrainingState:
    """Everything :func:`train_torch_ppo` needs to continue after ``iteration``.

    Attributes:
        iteration: Iterations done.
        timesteps: Env steps taken.
        seconds: Wall time of the training loop so far.
        model: The actor-critic's state dict (weights and observation statistics).
        optimizer: Adam's state dict (moments and step counts).
        generator: The device generator's state (a CPU byte tensor).
        ret_stats: The running (count, mean, variance) of the discounted return.
        history: The per-iteration records so far.
    """

    iteration: int
    timesteps: int
    seconds: float
    model: dict[str, torch.Tensor]
    optimizer: dict[str, Any]
    generator: torch.Tensor
    ret_stats: torch.Tensor
    history: list[dict[str, float]] = field(default_factory=list)


def make_torch_env(
    gym_id: str, num_envs: int, device: str, **env_kwargs: Any
) -> gym.vector.VectorEnv:
    """The torch vector env of ``gym_id`` on ``device``, in ``SAME_STEP`` autoreset mode."""
    return gym.make_vec(
        gym_id,
        num_envs=num_envs,
        vectorization_mode="vector_entry_point",
        backend="torch",
        device=device,
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
        **env_kwargs,
    )


def train_torch_ppo(
    env: gym.vector.VectorEnv,
    config: TorchPPOConfig,
    seed: int = 0,
    stop: Callable[[], bool] | None = None,
    log: Callable[[dict[str, float], TorchPolicy], None] | None = None,
    resume: TrainingState | None = None,
    checkpoint: Callable[[TrainingState], None] | None = None,
    checkpoint_freq: int = 0,
) -> TorchPPOResult:
    """Train a policy on a torch vector env (SAME_STEP autoreset) with PPO, all on its device.

    Args:
        env: From :func:`make_torch_env` (B = ``config.num_envs`` members).
        config: Hyperparameters.
        seed: Seed of the network's initial weights, the device generator and the env.
        stop: Polled once per iteration; True ends training after the current iteration.
        log: Called after each iteration with its history record and the current policy.
        resume: A state from ``checkpoint`` to continue from (same config and env): weights,
            Adam's state, the generator, the return statistics and the counters are restored;
            the env members start fresh episodes (reset with a seed derived from ``seed`` and
            the iteration), so a resumed run is not bit-identical to an uninterrupted one.
        checkpoint: Called with the current state after the first iteration at or past every
            multiple of ``checkpoint_freq`` env steps and after the last iteration (also when
            ``stop()`` ended training).
        checkpoint_freq: Env steps between checkpoints (0: the last iteration only).

    Raises:
        ValueError: For an env that is not a torch vector env in SAME_STEP mode, or whose B
            differs from ``config.num_envs``, a bad ``checkpoint_freq``, or a ``resume`` state
            that does not fit the network.
        agents.interrupt.Diverged: When an iteration's loss, gradient or weights are not
            finite (before its evaluation and checkpoint: the last checkpoint is a good one).
    """
    if getattr(env, "backend", None) != "torch":
        raise ValueError("env must be a torch vector env (make_torch_env / backend='torch')")
    if env.num_envs != config.num_envs:
        raise ValueError(f"env has {env.num_envs} members, config.num_envs is {config.num_envs}")
    if env.metadata.get("autoreset_mode") != gym.vector.AutoresetMode.SAME_STEP:
        raise ValueError("env must run in AutoresetMode.SAME_STEP (make_torch_env does)")
    check_int("seed", seed, 0, 2**63 - 1)
    check_int("checkpoint_freq", checkpoint_freq, 0)
    device = torch.device(env.device)
    B, T = config.num_envs, config.num_steps
    torch.manual_seed(seed)
    spec = PolicySpec.of(
        env.single_observation_space,
        env.single_action_space,
        hidden=tuple(config.hidden),
        init_log_std=config.init_log_std,
    )
    if resume is not None:
        if resume.timesteps != resume.iteration * B * T:
            raise ValueError(
                f"resume state: {resume.timesteps} env steps after {resume.iteration} iterations "
                f"of {B} x {T}: it is not a state of this config"
            )
        check_shapes(spec, resume.model, "resume state does not fit this network and config")
    model = ActorCritic(spec).to(device)
    if config.stop_prob is not None and resume is None:
        if spec.kind != "discrete" or spec.n < 2:
            raise ValueError("stop_prob applies to Discrete actions (2 or more)")
        with torch.no_grad():  # the output layer's weights are tiny: the logits start at it
            bias = model.actor[-1].bias
            bias.zero_()
            bias[0] = math.log(config.stop_prob / (1 - config.stop_prob) * (spec.n - 1))
    gen = torch.Generator(device=device).manual_seed(seed)
    params = list(model.parameters())
    # foreach: one kernel per step for all tensors, the single-tensor loop's results bit for bit
    optimizer = torch.optim.Adam(params, lr=config.learning_rate, eps=1e-5, foreach=True)
    masked = spec.kind == "discrete"
    d = spec.obs_dim
    act_shape = () if masked else (spec.n,)
    f32 = dict(device=device, dtype=torch.float32)

    obs_buf = torch.zeros((T, B, d), **f32)
    act_buf = torch.zeros(
        (T, B, *act_shape), device=device, dtype=torch.int64 if masked else torch.float32
    )
    logp_buf = torch.zeros((T, B), **f32)
    rew_buf = torch.zeros((T, B), **f32)
    done_buf = torch.zeros((T, B), **f32)
    val_buf = torch.zeros((T, B), **f32)
    mask_buf = torch.ones((T, B, spec.n), device=device, dtype=torch.bool) if masked else None

    # running std of the discounted return, for reward scaling (a scalar, on the device)
    ret = torch.zeros(B, device=device, dtype=torch.float64)
    ret_stats = torch.tensor([0.0, 0.0, 1.0], device=device, dtype=torch.float64)  # n, mean, var
    ep_return = torch.zeros(B, device=device, dtype=torch.float64)

    history: list[dict[str, float]] = []
    timesteps, interrupted, first, offset = 0, False, 1, 0.0
    if resume is not None:
        _restore(resume, model, optimizer, gen, ret_stats)
        history = list(resume.history)
        timesteps, first, offset = resume.timesteps, resume.iteration + 1, resume.seconds
    next_obs, _ = env.reset(seed=seed if resume is None else _resume_seed(seed, resume.iteration))
    start = time.perf_counter() - offset
    last_saved = timesteps

    def state(iteration: int) -> TrainingState:
        return TrainingState(
            iteration=iteration,
            timesteps=timesteps,
            seconds=time.perf_counter() - start,
            model={k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
            optimizer=_to_cpu(optimizer.state_dict()),
            generator=gen.get_state(),
            ret_stats=ret_stats.detach().cpu().clone(),
            history=list(history),
        )

    iteration = first - 1
    for iteration in range(first, config.iterations + 1):
        frac = 1.0 - (iteration - 1) / config.iterations if config.anneal_lr else 1.0
        lr = frac * config.learning_rate
        for group in optimizer.param_groups:
            group["lr"] = lr
        ended_sum = torch.zeros((), device=device, dtype=torch.float64)
        ended_n = torch.zeros((), device=device, dtype=torch.float64)
        with torch.no_grad():
            for t in range(T):
                if config.norm_obs:
                    model.update_obs_stats(next_obs)
                x = model.normalize(next_obs)
                mask = env.action_masks() if masked else None
                action, logp = model.act(x, mask, gen)  # one pass of the actor
                obs_buf[t] = x
                act_buf[t] = action
                logp_buf[t] = logp
                val_buf[t] = model.value(x)
                if masked:
                    mask_buf[t] = mask
                next_obs, reward, terminated, truncated, infos = env.step(model.to_env(action))
                reward = reward.double()
                ep_return += reward
                ended = terminated | truncated
                ended_sum += torch.where(ended, ep_return, 0.0).sum()
                ended_n += ended.sum()
                ep_return = torch.where(ended, 0.0, ep_return)
                if config.norm_reward:
                    ret = ret * config.gamma + reward
                    _fold(ret_stats, ret)
                    ret = torch.where(ended, 0.0, ret)
                    reward = reward / torch.sqrt(ret_stats[2] + 1e-8)
                cut = truncated & ~terminated
                if bool(cut.any()):  # bootstrap a truncated member from its last observation
                    final = model.normalize(infos["final_obs"])
                    reward = reward + config.gamma * torch.where(cut, model.value(final), 0.0)
                rew_buf[t] = reward.float()
                done_buf[t] = ended.float()
            next_value = model.value(model.normalize(next_obs))
            adv = gae(rew_buf, val_buf, done_buf, next_value, config.gamma, config.gae_lambda)
            returns = adv + val_buf
        timesteps += B * T

        b_obs, b_act = obs_buf.reshape(B * T, d), act_buf.reshape(B * T, *act_shape)
        b_logp, b_adv, b_ret = logp_buf.reshape(-1), adv.reshape(-1), returns.reshape(-1)
        # a rollout where every action was legal needs no masking (one host sync)
        b_mask = mask_buf.reshape(B * T, spec.n) if masked and not mask_buf.all() else None
        mb = B * T // config.num_minibatches
        first_bad = torch.zeros((), device=device, dtype=torch.int8)  # 1 loss, 2 gradient
        for _ in range(config.update_epochs):
            order = torch.randperm(B * T, generator=gen, device=device)
            for k in range(config.num_minibatches):
                idx = order[k * mb : (k + 1) * mb]
                obs = b_obs[idx]
                new_logp, entropy = model.log_prob_entropy(
                    obs, b_act[idx], None if b_mask is None else b_mask[idx]
                )
                ratio = (new_logp - b_logp[idx]).exp()
                a = b_adv[idx]
                if config.norm_adv and a.numel() > 1:
                    a = (a - a.mean()) / (a.std() + 1e-8)
                pg_loss = torch.max(
                    -a * ratio, -a * ratio.clamp(1 - config.clip_coef, 1 + config.clip_coef)
                ).mean()
                v_loss = 0.5 * ((model.value(obs) - b_ret[idx]) ** 2).mean()
                loss = pg_loss - config.ent_coef * entropy.mean() + config.vf_coef * v_loss
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                norm = nn.utils.clip_grad_norm_(params, config.max_grad_norm)
                now = torch.where(~torch.isfinite(loss.detach()), 1, 2 * ~torch.isfinite(norm))
                first_bad = torch.where(first_bad == 0, now.to(first_bad.dtype), first_bad)
                optimizer.step()
        _check_finite(model, first_bad, timesteps)

        n_ended = float(ended_n)  # one host sync per iteration
        record = {
            "iteration": iteration,
            "timesteps": timesteps,
            "seconds": time.perf_counter() - start,
            "episodes": n_ended,
            "mean_return": float(ended_sum) / n_ended if n_ended else math.nan,
            "learning_rate": lr,
        }
        history.append(record)
        if log is not None:
            log(record, TorchPolicy(model, seed))
            model.train()
        stopping = stop is not None and stop()
        due = checkpoint_freq and timesteps // checkpoint_freq > last_saved // checkpoint_freq
        if checkpoint is not None and (due or stopping or iteration == config.iterations):
            checkpoint(state(iteration))
            last_saved = timesteps
        if stopping:
            interrupted = iteration < config.iterations
            break
    seconds = time.perf_counter() - start
    return TorchPPOResult(TorchPolicy(model, seed), timesteps, seconds, history, interrupted)


def _check_finite(model: ActorCritic, first_bad: torch.Tensor, timesteps: int) -> None:
    """Raise :class:`~agents.interrupt.Diverged` after an iteration that went non-finite.

    ``first_bad`` is the iteration's flag on the device (0: fine; 1: a loss, 2: a gradient
    was the first non-finite value); the weights and observation statistics are checked too,
    in one host sync.

    Raises:
        Diverged: Naming the first of the loss, the gradient or a tensor that is not finite.
    """
    from agents.interrupt import Diverged

    state = [(k, v) for k, v in model.state_dict().items() if v.is_floating_point()]
    bad = [(~torch.isfinite(v).all()).long() for _, v in state]
    flags = torch.stack([first_bad.long(), *bad])
    first, *tensors = flags.cpu().tolist()
    if first:
        raise Diverged("the loss" if first == 1 else "the gradient", timesteps)
    if any(tensors):
        raise Diverged(f"the network's {state[tensors.index(True)][0]}", timesteps)


def _resume_seed(seed: int, iteration: int) -> int:
    """The env's reset seed when a run resumes after ``iteration`` (fresh episodes)."""
    return int(np.random.SeedSequence([seed, iteration]).generate_state(1, np.uint64)[0] >> 1)


def _to_cpu(obj: Any) -> Any:
    """A copy of a (nested) state dict with every tensor on the CPU."""
    if isinstance(obj, torch.Tensor):
        return obj.detach().cpu().clone()
    if isinstance(obj, dict):
        return {k: _to_cpu(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_to_cpu(v) for v in obj]
    return obj


def _restore(
    resume: TrainingState,
    model: ActorCritic,
    optimizer: torch.optim.Optimizer,
    gen: torch.Generator,
    ret_stats: torch.Tensor,
) -> None:
    """Load a :class:`TrainingState` into a freshly built model, optimizer and generator."""
    try:
        model.load_state_dict(resume.model, strict=True)
        optimizer.load_state_dict(_to_cpu(resume.optimizer))  # a copy: Adam updates in place
        for group in optimizer.param_groups:  # a state saved without foreach keeps its speed
            group["foreach"] = True
        gen.set_state(resume.generator.cpu())
        ret_stats.copy_(resume.ret_stats.to(ret_stats))
    except (KeyError, RuntimeError, ValueError, TypeError) as exc:
        raise ValueError(f"resume state does not fit this network and config: {exc}") from None


def gae(
    rewards: torch.Tensor,
    values: torch.Tensor,
    dones: torch.Tensor,
    next_value: torch.Tensor,
    gamma: float,
    lam: float,
) -> torch.Tensor:
    """Generalised advantage estimates of a (T, B) rollout.

    ``dones[t]`` is 1 where the member's episode ended at step t (its ``values[t + 1]`` is the
    next episode's start and is not bootstrapped); ``next_value`` (B,) is V of the observation
    after the last step. ``A_t = δ_t + γλ(1 − d_t) A_{t+1}``, ``δ_t = r_t + γ(1 − d_t)
    V_{t+1} − V_t``.
    """
    T = rewards.shape[0]
    adv = torch.zeros_like(rewards)
    last = torch.zeros_like(next_value)
    for t in reversed(range(T)):
        value_next = next_value if t == T - 1 else values[t + 1]
        nonterminal = 1.0 - dones[t]
        delta = rewards[t] + gamma * value_next * nonterminal - values[t]
        last = delta + gamma * lam * nonterminal * last
        adv[t] = last
    return adv


def _fold(stats: torch.Tensor, x: torch.Tensor) -> None:
    """Fold the batch ``x`` into ``stats = [n, mean, var]`` in place (on the device)."""
    n, mean, var = stats[0], stats[1], stats[2]
    m = x.numel()
    b_mean, b_var = x.mean(), x.var(unbiased=False)
    total = n + m
    delta = b_mean - mean
    new_var = (var * n + b_var * m + delta**2 * n * m / total) / total
    stats.copy_(torch.stack([total, mean + delta * m / total, new_var]))


# ---------------------------------------------------------------------------- checkpoints


def save_policy(
    policy: TorchPolicy,
    path: Path,
    config: TorchPPOConfig | None = None,
    num_timesteps: int = 0,
) -> Path:
    """Write ``path.with_suffix(".pt")`` (tensors only) and its ``.json`` (``save_pair``).

    The ``.pt`` holds ``{"state_dicts": {"policy": ...}, "variables": {}}`` (what
    :func:`agents.checkpoint.load_tensors` accepts); the ``.json`` the format, the network's
    :class:`PolicySpec`, the hyperparameters, the step count and the ``.pt``'s SHA-256.
    Returns the ``.json`` path.
    """
    path = Path(path)
    state = {k: v.detach().cpu().clone() for k, v in policy.model.state_dict().items()}
    payload = {"state_dicts": {"policy": state}, "variables": {}}
    spec = asdict(policy.spec)
    meta = {
        "format": FORMAT,
        "algo": ALGO,
        "spec": {k: list(v) if isinstance(v, tuple) else v for k, v in spec.items()},
        "hyperparameters": None if config is None else _jsonable(asdict(config)),
        "num_timesteps": int(num_timesteps),
    }
    return save_pair(path.with_suffix(".json"), path.with_suffix(".pt"), payload, meta)


def load_policy(path: Path, root: Path, device: str = "cpu", seed: int = 0) -> TorchPolicy:
    """The policy :func:`save_policy` wrote at ``path`` (its ``.json``), on ``device``.

    Raises:
        ValueError: For a path outside ``root``, a missing or corrupt file, another format, a
            SHA-256 mismatch, a tensor file holding anything but tensors, or weights that do not
            fit the network the JSON describes.
    """
    path = inside(Path(path).parent, Path(path).name, root, "model file")
    meta = read_json(path, "model description")
    if meta.get("format") != FORMAT:
        raise ValueError(f"model description {path}: format {meta.get('format')!r}, not {FORMAT}")
    check_count(meta.get("num_timesteps", 0), "num_timesteps", path)
    config = meta.get("hyperparameters")
    if config is not None:
        known = {f.name for f in fields(TorchPPOConfig)}
        unknown = (
            sorted(str(k) for k in config)
            if not isinstance(config, dict)
            else sorted(str(k) for k in config if k not in known)
        )
        try:
            if unknown:
                raise ValueError(f"unknown key(s) {', '.join(unknown)}; known: {', '.join(known)}")
            TorchPPOConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in config.items()})
        except (TypeError, ValueError, AttributeError) as exc:
            raise ValueError(f"model description {path}: bad hyperparameters ({exc})") from None
    spec = _spec_of(meta.get("spec"), path)
    tensors = tensor_file(meta, path, root)
    payload = load_tensors(tensors, device)
    state = payload["state_dicts"].get("policy")
    check_shapes(spec, state, f"tensor file {tensors} does not hold the network {path} describes")
    model = ActorCritic(spec).to(device)
    try:
        model.load_state_dict(state, strict=True)
    except (KeyError, RuntimeError, TypeError) as exc:
        raise ValueError(
            f"checkpoint {tensors} does not fit the network of {path}: {exc}"
        ) from None
    return TorchPolicy(model, seed)


def _spec_of(raw: Any, path: Path) -> PolicySpec:
    """The :class:`PolicySpec` a model description holds, checked (naming ``path``)."""
    try:
        if not isinstance(raw, dict):
            raise TypeError(f"expected a JSON object, got {raw!r:.80}")
        raw = dict(raw)
        for key in ("hidden", "low", "high"):
            value = raw.get(key, ())
            if not isinstance(value, list | tuple):
                raise TypeError(f"{key} must be a list, got {value!r:.80}")
            raw[key] = tuple(value)
        spec = PolicySpec(**raw)
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"model description {path}: bad network spec ({exc})") from None
    if not isinstance(spec.init_log_std, int | float) or isinstance(spec.init_log_std, bool):
        raise ValueError(f"model description {path}: bad network spec (init_log_std)")
    return spec


def check_shapes(spec: PolicySpec, state: Any, refusal: str) -> None:
    """Raise unless ``state`` holds exactly the tensors of ``spec``'s network, by name and shape.

    The network is laid out on torch's ``meta`` device (no memory), so a description asking
    for a network far larger than its tensor file is refused before anything is allocated.

    Raises:
        ValueError: ``refusal`` (naming the files), and the first tensor that differs.
    """
    with torch.device("meta"):
        wanted = {k: tuple(v.shape) for k, v in ActorCritic(spec).state_dict().items()}
    if not isinstance(state, dict):
        raise ValueError(f"{refusal}: it holds no policy state dict")
    got = {k: tuple(v.shape) if isinstance(v, torch.Tensor) else None for k, v in state.items()}
    if got != wanted:
        name = sorted(k for k in wanted.keys() | got.keys() if wanted.get(k) != got.get(k))[0]
        raise ValueError(
            f"{refusal}: {name} has shape {got.get(name)}, the network needs {wanted.get(name)}"
        )


STATE_FORMAT = "fdia_env-torch-ppo-state-v1"


def save_training_state(state: TrainingState, path: Path) -> Path:
    """Write a :class:`TrainingState`: ``path.with_suffix(".pt")`` (tensors only), then ``path``.

    The ``.pt`` holds the model's and Adam's state dicts and the generator and return
    statistics (what :func:`agents.checkpoint.load_tensors` accepts); the JSON the counters, the
    per-iteration history and the ``.pt``'s SHA-256. They are written by
    :func:`agents.checkpoint.save_pair`, so a run killed at any moment of the write keeps a
    state that ``--resume`` continues (the previous one, or the new one when only the last move
    was missing). Returns the JSON path.

    Raises:
        OSError: When a file cannot be written (a full disk), naming it.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "state_dicts": {"policy": state.model, "optimizer": state.optimizer},
        "variables": {"generator": state.generator, "ret_stats": state.ret_stats},
    }
    meta = {
        "format": STATE_FORMAT,
        "iteration": int(state.iteration),
        "timesteps": int(state.timesteps),
        "seconds": float(state.seconds),
        "history": state.history,
    }
    return save_pair(path, path.with_suffix(".pt"), payload, meta)


def load_training_state(path: Path, root: Path) -> TrainingState:
    """The :class:`TrainingState` :func:`save_training_state` wrote at ``path`` (on the CPU).

    Raises:
        ValueError: For a path outside ``root``, a missing or corrupt file, another format, a
            SHA-256 mismatch or a tensor file holding anything but tensors.
    """
    path = inside(Path(path).parent, Path(path).name, root, "training state")
    meta = read_json(path, "training state")
    if meta.get("format") != STATE_FORMAT:
        fmt = meta.get("format")
        raise ValueError(f"training state {path}: format {fmt!r}, not {STATE_FORMAT}")
    iteration = check_count(meta.get("iteration"), "iteration", path)
    timesteps = check_count(meta.get("timesteps"), "timesteps", path, MAX_COUNT)
    seconds = check_seconds(meta.get("seconds"), "seconds", path)
    history = meta.get("history", [])
    if not isinstance(history, list) or not all(isinstance(h, dict) for h in history):
        raise ValueError(f"{path} is corrupt: history must be a list of JSON objects")
    tensors = tensor_file(meta, path, root)
    payload = load_tensors(tensors, "cpu")
    try:
        state = TrainingState(
            iteration=iteration,
            timesteps=timesteps,
            seconds=seconds,
            model=payload["state_dicts"]["policy"],
            optimizer=payload["state_dicts"]["optimizer"],
            generator=payload["variables"]["generator"],
            ret_stats=payload["variables"]["ret_stats"],
            history=list(history),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"training state {path} is incomplete ({exc})") from None
    for name in ("generator", "ret_stats"):
        if not isinstance(getattr(state, name), torch.Tensor):
            raise ValueError(f"training state {tensors}: {name} is not a tensor")
    return state


def _jsonable(d: dict[str, Any]) -> dict[str, Any]:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}
