"""Hyperparameters and run settings, one dataclass per command, docstring per field.

``train.py`` parses these with tyro (``python train.py attacker --help`` shows every field with
its docstring and default). Hyperparameters left at ``None`` take the algorithm's default from
:data:`ALGO_DEFAULTS`, tuned for these short episodic envs (a window of a few steps, so no
discounting: ``gamma = 1``); :func:`algo_kwargs` resolves them into stable-baselines3 kwargs.

>>> kwargs = algo_kwargs("DQN", Hyperparameters(learning_rate=5e-4))
>>> kwargs["learning_rate"], kwargs["buffer_size"], kwargs["policy_kwargs"]
(0.0005, 50000, {'net_arch': [64, 64]})
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import tyro

from agents.options import check_choice, check_number, flag

_PPO = {
    "learning_rate": 1e-3,
    "gamma": 1.0,
    "n_steps": 512,
    "batch_size": 128,
    "n_epochs": 10,
    "ent_coef": 0.01,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "lr_schedule": "linear",
    "net_arch": (64, 64),
    "stop_prob": None,
}

# Per algorithm: every hyperparameter that applies to it, with its default.
ALGO_DEFAULTS: dict[str, dict[str, Any]] = {
    "PPO": dict(_PPO),
    "MaskablePPO": dict(_PPO),
    "A2C": {
        "learning_rate": 7e-4,
        "gamma": 1.0,
        "n_steps": 16,
        "ent_coef": 0.01,
        "gae_lambda": 1.0,
        "lr_schedule": "linear",
        "net_arch": (64, 64),
        "stop_prob": None,
    },
    "DQN": {
        "learning_rate": 1e-3,
        "gamma": 1.0,
        "batch_size": 64,
        "buffer_size": 50_000,
        "learning_starts": 1_000,
        "train_freq": 4,
        "target_update_interval": 1_000,
        "exploration_fraction": 0.3,
        "exploration_final_eps": 0.02,
        "lr_schedule": "constant",
        "net_arch": (64, 64),
    },
    "SAC": {
        "learning_rate": 1e-3,
        "gamma": 1.0,
        "batch_size": 256,
        "buffer_size": 100_000,
        "learning_starts": 1_000,
        "train_freq": 1,
        "tau": 0.005,
        "lr_schedule": "constant",
        "net_arch": (64, 64),
    },
    # agents/torch_ppo.py: env, buffer and policy on the device; n_steps per member per rollout
    # (one rollout = num_envs × n_steps steps), 4 minibatches per epoch
    "torch-ppo": {
        **{k: v for k, v in _PPO.items() if k != "batch_size"},  # 4 minibatches per epoch
        "learning_rate": 3e-3,
        "n_steps": 12,
        "n_epochs": 4,
        "norm_obs": True,
    },
}

TORCH_PPO = "torch-ppo"
# torch-ppo's default batch of members on the device (--num-envs)
TORCH_PPO_NUM_ENVS = 4096
MAX_NUM_ENVS = 2**24


def is_torch_ppo(algo: str | None) -> bool:
    """Whether ``--algo`` names the torch-native PPO (case, ``-`` and ``_`` insensitive)."""
    return isinstance(algo, str) and algo.replace("_", "").replace("-", "").lower() == "torchppo"


MAX_SEED = 2**32 - 1
BACKENDS = ("sb3", "rllib")

# Per numeric option: integer or real, whether it accepts a value, and the allowed values.
_Rule = tuple[type, Callable[[float], bool], str]
_AT_LEAST_1: _Rule = (int, lambda v: v >= 1, ">= 1")
_AT_LEAST_0: _Rule = (int, lambda v: v >= 0, ">= 0")
_UNIT: _Rule = (float, lambda v: 0 <= v <= 1, "in [0, 1]")
_HYPERPARAMETER_RULES: dict[str, _Rule] = {
    "learning_rate": (float, lambda v: v > 0, "> 0"),
    "gamma": (float, lambda v: 0 < v <= 1, "in (0, 1]"),
    "n_steps": _AT_LEAST_1,
    "batch_size": _AT_LEAST_1,
    "n_epochs": _AT_LEAST_1,
    "ent_coef": (float, lambda v: v >= 0, ">= 0"),
    "gae_lambda": _UNIT,
    "clip_range": (float, lambda v: v > 0, "> 0"),
    "buffer_size": _AT_LEAST_1,
    "learning_starts": _AT_LEAST_0,
    "train_freq": _AT_LEAST_1,
    "target_update_interval": _AT_LEAST_1,
    "exploration_fraction": _UNIT,
    "exploration_final_eps": _UNIT,
    "tau": (float, lambda v: 0 < v <= 1, "in (0, 1]"),
    "stop_prob": (float, lambda v: 0 < v < 1, "in (0, 1)"),
}


def check_device_name(device: object) -> None:
    """Raise unless ``device`` names a torch device (``cpu``, ``cuda``, ``cuda:1``, ``auto``).

    Whether the device is present is checked by :func:`check_device_available`.

    Raises:
        ValueError: For any other string.
    """
    import torch

    if device == "auto":
        return
    try:
        torch.device(device)
    except (RuntimeError, TypeError):
        raise ValueError(
            f"{flag('device')} must be cpu, cuda, cuda:<index>, mps or auto, got {device!r}"
        ) from None


def resolve_device(device: str) -> str:
    """``--device`` as a torch device name: ``auto`` is cuda when present, else cpu."""
    import torch

    if device == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    return device


def check_device_available(device: str) -> None:
    """Raise unless ``device`` is present on this machine (``auto`` always is).

    Raises:
        ValueError: For CUDA or MPS without one, or a CUDA index beyond the devices present.
    """
    import torch

    check_device_name(device)
    if device == "auto":
        return
    dev = torch.device(device)
    if dev.type == "cuda":
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if count == 0:
            raise ValueError(
                f"{flag('device')}: {device!r} asked for but CUDA is not available here "
                f"(torch {torch.__version__}); use --device cpu"
            )
        if dev.index is not None and dev.index >= count:
            raise ValueError(
                f"{flag('device')}: {device!r} asked for but this machine has {count} CUDA "
                f"device(s), cuda:0 to cuda:{count - 1}"
            )
    elif dev.type == "mps" and not torch.backends.mps.is_available():
        raise ValueError(f"{flag('device')}: 'mps' asked for but MPS is not available here")
    elif dev.type not in ("cpu", "cuda", "mps"):
        raise ValueError(f"{flag('device')} must be cpu, cuda, cuda:<index>, mps or auto")


@dataclass
class Hyperparameters:
    """stable-baselines3 hyperparameters; ``None`` means the algorithm's default."""

    learning_rate: float | None = None
    """Adam step size (default: 1e-3; A2C 7e-4; torch-ppo 3e-3)."""
    gamma: float | None = None
    """Discount factor (default: 1.0, the windows are a few steps long)."""
    n_steps: int | None = None
    """PPO/A2C: steps per rollout (default: PPO 512, A2C 16; torch-ppo: 12 per member)."""
    batch_size: int | None = None
    """PPO minibatch / DQN and SAC replay batch (default: PPO 128, DQN 64, SAC 256)."""
    n_epochs: int | None = None
    """PPO: optimisation epochs per rollout (default: 10; torch-ppo 4)."""
    ent_coef: float | None = None
    """PPO/A2C: entropy bonus (default: 0.01)."""
    gae_lambda: float | None = None
    """PPO/A2C: GAE lambda (default: PPO 0.95, A2C 1.0)."""
    clip_range: float | None = None
    """PPO: clipping range (default: 0.2)."""
    buffer_size: int | None = None
    """DQN/SAC: replay buffer size (default: DQN 50,000, SAC 100,000)."""
    learning_starts: int | None = None
    """DQN/SAC: steps before learning starts (default: 1,000)."""
    train_freq: int | None = None
    """DQN/SAC: environment steps per gradient update (default: DQN 4, SAC 1)."""
    target_update_interval: int | None = None
    """DQN: steps between target-network updates (default: 1,000)."""
    exploration_fraction: float | None = None
    """DQN: fraction of training over which epsilon decays (default: 0.3)."""
    exploration_final_eps: float | None = None
    """DQN: final epsilon (default: 0.02)."""
    tau: float | None = None
    """SAC: soft target-update rate (default: 0.005)."""
    lr_schedule: Literal["constant", "linear"] | None = None
    """Learning rate over training: constant, or linear decay to 0 (default: PPO/A2C linear)."""
    net_arch: tuple[int, ...] | None = None
    """Hidden layer sizes of the policy and value networks (default: 64 64)."""
    stop_prob: float | None = None
    """PPO/MaskablePPO/A2C/torch-ppo: initial probability of action 0 (the sequential format's stop)
    when every action is legal, set through the policy's output bias (default: none, uniform;
    the grid presets' sparse attack: 0.9, so that early episodes keep budget for late steps)."""
    norm_obs: bool | None = None
    """torch-ppo: running normalisation of the observations, kept in the policy (default: on;
    the grid presets' sparse attack: off, as in the results table, where torch-ppo in the
    plan-first order reached 46 % of the optimum on ieee14-rtu with it and 100 % without)."""

    def __post_init__(self) -> None:
        for name, (kind, ok, allowed) in _HYPERPARAMETER_RULES.items():
            value = getattr(self, name)
            if value is not None:
                check_number(name, value, kind, ok, allowed)
        if self.norm_obs is not None and not isinstance(self.norm_obs, bool):
            raise TypeError(f"{flag('norm_obs')} must be True or False, got {self.norm_obs!r}")
        if self.lr_schedule is not None:
            check_choice("lr_schedule", self.lr_schedule, ("constant", "linear"))
        if self.net_arch is not None:
            if not isinstance(self.net_arch, tuple | list):
                raise TypeError(f"{flag('net_arch')} must be a sequence of layer sizes")
            for size in self.net_arch:
                check_number("net_arch", size, int, lambda v: v >= 1, ">= 1 (each layer size)")


HYPERPARAMETERS = tuple(f.name for f in dataclasses.fields(Hyperparameters))


class LinearSchedule:
    """SB3 learning-rate schedule ``lr × progress_remaining`` (1 at the start, 0 at the end).

    A class rather than a closure so that saved models unpickle it by name.
    """

    def __init__(self, initial: float) -> None:
        self.initial = float(initial)

    def __call__(self, progress_remaining: float) -> float:
        """The learning rate at ``progress_remaining`` ∈ [0, 1]."""
        return self.initial * progress_remaining

    def __repr__(self) -> str:
        return f"LinearSchedule({self.initial!r})"


def resolved_hyperparameters(algo: str, hp: Hyperparameters) -> dict[str, Any]:
    """Every hyperparameter that applies to ``algo`` with the value used (for config.json).

    Raises:
        ValueError: For an unknown algorithm, or a hyperparameter set in ``hp`` that does not
            apply to ``algo`` (naming the algorithms it applies to).
    """
    if algo not in ALGO_DEFAULTS:
        raise ValueError(
            f"unknown algorithm {algo!r}; valid algorithms: {', '.join(ALGO_DEFAULTS)}"
        )
    values = dict(ALGO_DEFAULTS[algo])
    for name in HYPERPARAMETERS:
        given = getattr(hp, name)
        if given is None:
            continue
        if name not in values:
            users = [a for a, d in ALGO_DEFAULTS.items() if name in d]
            raise ValueError(f"{name} does not apply to {algo}; it applies to: {', '.join(users)}")
        values[name] = given
    if algo in ("PPO", "MaskablePPO"):  # torch-ppo's minibatches are num_envs·n_steps / 4
        for name in ("n_steps", "batch_size"):
            if values[name] < 2:
                raise ValueError(
                    f"{flag(name)} must be >= 2 for {algo} (it normalises advantages over a "
                    f"minibatch), got {values[name]}"
                )
    if values["lr_schedule"] not in ("constant", "linear"):
        raise ValueError(
            f"lr_schedule must be 'constant' or 'linear', got {values['lr_schedule']!r}"
        )
    values["net_arch"] = list(values["net_arch"])
    return values


def algo_kwargs(algo: str, hp: Hyperparameters) -> dict[str, Any]:
    """stable-baselines3 constructor kwargs of ``algo``: its defaults updated with ``hp``.

    Raises:
        ValueError: As :func:`resolved_hyperparameters`.
    """
    kwargs = resolved_hyperparameters(algo, hp)
    if kwargs.pop("lr_schedule") == "linear":
        kwargs["learning_rate"] = LinearSchedule(kwargs["learning_rate"])
    kwargs["policy_kwargs"] = {"net_arch": kwargs.pop("net_arch")}
    if kwargs.get("stop_prob", 0) is None:  # agents.algos.build_model applies it
        del kwargs["stop_prob"]
    return kwargs


@dataclass(frozen=True)
class ScenarioDefaults:
    """What ``train.py`` uses by default on one scenario preset of one env.

    Attributes:
        env_kwargs: Env options of the preset (``--env-kwargs`` given on the command line
            override them).
        algo: Default algorithm of the attacker and defender commands (None: the env's first).
        hyperparameters: Hyperparameters that replace the algorithm's defaults
            (:data:`ALGO_DEFAULTS`) where they apply to the algorithm run and the command line
            leaves them unset.
        normalize_reward: Train on the rewards rescaled by the reference (see
            :func:`agents.training.reward_normalization`); evaluation is always on the raw
            rewards.
        when: The defaults apply only when the run's env options include these (e.g. the
            sequential action format; with ``--env-kwargs action '"multibinary"'`` the
            algorithm's own defaults are used); a tuple value allows any of its values.
        num_envs: MaskablePPO trains on the env's native vector env of this many members
            where the command line gives neither ``--num-envs`` nor ``--n-steps`` (either one
            replaces this and ``vector_hyperparameters``). None: one env.
        vector_hyperparameters: Hyperparameters of that vector setting (``n_steps`` is per
            member), before ``hyperparameters``; the command line still wins.
    """

    env_kwargs: dict[str, Any] = field(default_factory=dict)
    algo: str | None = None
    hyperparameters: dict[str, Any] = field(default_factory=dict)
    normalize_reward: bool = False
    when: dict[str, Any] = field(default_factory=dict)
    num_envs: int | None = None
    vector_hyperparameters: dict[str, Any] = field(default_factory=dict)


# The grid presets' sparse attack is built one pair per decision (the sequential format in its
# plan-first order: at most c picks of Discrete(N·M + 1), then stop), with the action mask for
# MaskablePPO; the time-major order does not learn there (docs/guide/sparse.md, decision
# order). The algorithm's own defaults, rewards normalised, and the env's order="increasing":
# a plan's pairs picked in increasing order, one sequence of picks per plan, so the entropy
# bonus explores other plans (``--env-kwargs order '"plan"'`` allows every order of the picks,
# with the same defaults otherwise). MaskablePPO trains on the native vector env of 8 members,
# 128 decisions each per rollout (1,024 per update, minibatches of 256): about 3 times one
# env's decisions per second, and the proved optimum on every seed measured (the training
# guide); 8 members of 64 (one env's 512 per update) stopped at SFS's set on 2 of 3 seeds.
_SEQUENTIAL = {"action": "sequential"}
_PLAN_FIRST = {"action": "sequential", "order": "plan"}
_INCREASING = {"action": "sequential", "order": "increasing"}
_GRID_SPARSE = ScenarioDefaults(
    env_kwargs=_INCREASING,
    algo="MaskablePPO",
    hyperparameters={"norm_obs": False},  # torch-ppo only (docs/guide/sparse.md)
    normalize_reward=True,
    when={"action": "sequential", "order": ("increasing", "plan")},
    num_envs=8,
    vector_hyperparameters={"n_steps": 128, "batch_size": 256},
)
_GRID_GAME = ScenarioDefaults(
    env_kwargs=_SEQUENTIAL,
    algo="MaskablePPO",
    hyperparameters={"n_steps": 256, "batch_size": 64, "ent_coef": 0.01},
    normalize_reward=True,
    when=_SEQUENTIAL,
)
GRID_PRESETS = ("grid-ieee14", "grid-ieee30", "grid-ieee57", "grid-ieee118")
SPARSE_ENVS = ("sparse_attack_v2", "sparse_attack_v1", "sparse_attack_v0")
"""The sparse attack's versions train.py trains, the newest (its default env) first."""
GAME_ITERATIONS = 8
"""``train.py game``'s default ``--iterations`` (a ``--task`` run of PSRO with exact best
responses runs to its fixed point instead: :attr:`GameConfig.converges`)."""
GAME_EXPECTED_REWARDS = ("grid-ieee14",)
"""Sensor-game presets whose SB3 best responses train on the expected reward over the other
side's mix by default (``train.py game --expected-rewards``): there the defender's strategies
differ by a few % of the game value, below the noise of one sampled opponent per episode."""

# The dc-ieee14-50 preset's sparse attack (300 pairs, c = 5, N = 6, trace; SFS stops at 98.51 %
# of branch and bound's proved optimum): the grid presets' format and reward scale, the
# plan-first order with the state groups (groups="state": one action adds every meter that sees
# one state at one window step) and more exploration (ent_coef 0.05). The optimum's four meters
# of bus 8 pay nothing until all four are dropped: pair by pair every learner stops at SFS's set
# (98.51 %); with the groups MaskablePPO reaches the proved optimum on every seed measured
# (docs/results/sparse_grid.md).
_DC_SPARSE = ScenarioDefaults(
    env_kwargs={**_PLAN_FIRST, "groups": "state"},
    algo="MaskablePPO",
    hyperparameters={"ent_coef": 0.05, "norm_obs": False},
    normalize_reward=True,
    when=_PLAN_FIRST,
    num_envs=_GRID_SPARSE.num_envs,  # reaches the proved optimum (docs/results/training_runs.md)
    vector_hyperparameters=_GRID_SPARSE.vector_hyperparameters,
)

SCENARIO_DEFAULTS: dict[tuple[str, str], ScenarioDefaults] = {
    **{(env, name): _GRID_SPARSE for env in SPARSE_ENVS for name in GRID_PRESETS},
    **{(env, "dc-ieee14-50"): _DC_SPARSE for env in SPARSE_ENVS},
    **{(env, "grid-ieee14-rtu"): _GRID_SPARSE for env in SPARSE_ENVS},
    ("sensor_game_v0", "grid-ieee14"): _GRID_GAME,
}
"""Per (env, scenario preset): ``train.py``'s defaults there (docs/guide/training.md lists them).

Scenarios not in the table train with the algorithm's defaults (:data:`ALGO_DEFAULTS`)."""


def scenario_defaults(env: str, scenario: str, env_kwargs: dict[str, Any]) -> ScenarioDefaults:
    """The defaults of ``env`` on ``scenario`` given the run's resolved env options.

    An empty :class:`ScenarioDefaults` where the table has none, or where the run's options
    leave the table's conditions (``when``), e.g. another action format.
    """
    found = SCENARIO_DEFAULTS.get((env, scenario))
    if found is None or not all(
        env_kwargs.get(k) in (v if isinstance(v, tuple) else (v,)) for k, v in found.when.items()
    ):
        return ScenarioDefaults()
    return found


def with_defaults(algo: str, hp: Hyperparameters, defaults: ScenarioDefaults) -> Hyperparameters:
    """``hp`` with each unset field that applies to ``algo`` taken from ``defaults``.

    Fields that the scenario's defaults set but ``algo`` does not take are left unset (a
    scenario tuned for MaskablePPO still runs DQN with DQN's defaults).
    """
    known = ALGO_DEFAULTS.get(algo, {})
    fill = {
        name: value
        for name, value in defaults.hyperparameters.items()
        if name in known and getattr(hp, name) is None
    }
    return dataclasses.replace(hp, **fill) if fill else hp


def parse_env_kwargs(raw: dict[str, str]) -> dict[str, Any]:
    """CLI env options with each value read as JSON where it parses, else kept as a string.

    >>> parse_env_kwargs({"budget": "4", "power": "1e3", "allocation": "dependent"})
    {'budget': 4, 'power': 1000.0, 'allocation': 'dependent'}
    """
    out: dict[str, Any] = {}
    for key, value in raw.items():
        try:
            out[key] = json.loads(value) if isinstance(value, str) else value
        except json.JSONDecodeError:
            out[key] = value
    return out


def check_env_kwargs_format(env_kwargs: object) -> None:
    """Raise unless ``env_kwargs`` maps option names (identifiers) to values.

    Which names an env accepts is checked against the env when it is built.

    Raises:
        TypeError: For something that is not a dict.
        ValueError: For a name that is not an identifier, or ``scenario`` (its own flag).
    """
    if not isinstance(env_kwargs, dict):
        raise TypeError(f"{flag('env_kwargs')} must map option names to values")
    for key in env_kwargs:
        if not isinstance(key, str) or not key.isidentifier():
            raise ValueError(
                f"{flag('env_kwargs')} takes name value pairs (e.g. --env-kwargs budget 4); "
                f"{key!r} is not an option name"
            )
        if key == "scenario":  # the scenario has its own flag (and the run folder's name)
            raise ValueError(
                f"{flag('env_kwargs')} must not set scenario; pass it with "
                f"{flag('scenario')} (e.g. --scenario ch3-tracking)"
            )


@dataclass
class RunSettings:
    """Where and how a run is written (shared by every command)."""

    seed: int = 0
    """Seed of Python, NumPy, torch, the algorithm and the environments."""
    runs_root: Path = Path("runs")
    """Folder that holds the run folders."""
    run_dir: Path | None = None
    """Run folder (default: <runs-root>/<env>-<algo>-s<seed>-<time>)."""
    resume: bool = False
    """Continue --run-dir (default: the latest run of this env, algo, seed) from its checkpoint."""
    progress_bar: bool = True
    """Show a progress bar while training."""
    torch_threads: int = 1
    """torch CPU threads (these small networks run fastest on one)."""
    device: str = "cpu"
    """torch device."""
    verbose: int = 0
    """stable-baselines3 verbosity (0: quiet, 1: training statistics)."""
    trust_checkpoint: bool = False
    """Allow --resume to load stable-baselines3 .zip / pickled replay buffers (older runs'
    checkpoints). These are unpickled and can run any code: only for files you trust."""
    backend: Literal["sb3", "rllib"] = "sb3"
    """sb3: stable-baselines3 in this process; rllib: Ray RLlib PPO, locally or on a Ray
    cluster (needs the fdia-env[rllib] extra)."""
    num_env_runners: int = 0
    """rllib: remote env runners sampling in parallel (0: sample in this process)."""
    envs_per_env_runner: int = 8
    """rllib: envs each env runner steps together (one batched forward pass)."""
    ray_address: str | None = None
    """rllib: address of a running Ray cluster (as `ray start --head` prints it, e.g.
    10.0.0.1:6379, or auto); default: start a local Ray."""
    num_cpus: int | None = None
    """rllib: CPUs of the local Ray (default: all); ignored with --ray-address."""
    sample_timeout_s: float = 600.0
    """rllib: seconds an iteration waits for its samples; one that gets none is an error."""

    def __post_init__(self) -> None:
        check_number("seed", self.seed, int, lambda v: 0 <= v <= MAX_SEED, f"in [0, {MAX_SEED}]")
        check_number("torch_threads", self.torch_threads, int, lambda v: v >= 1, ">= 1")
        check_number("verbose", self.verbose, int, lambda v: v in (0, 1, 2), "0, 1 or 2")
        check_device_name(self.device)
        check_choice("backend", self.backend, BACKENDS)
        check_number("num_env_runners", self.num_env_runners, *_AT_LEAST_0)
        check_number("envs_per_env_runner", self.envs_per_env_runner, *_AT_LEAST_1)
        if self.num_cpus is not None:
            check_number("num_cpus", self.num_cpus, *_AT_LEAST_1)
        if self.ray_address is not None and (
            not isinstance(self.ray_address, str) or not self.ray_address.strip()
        ):
            raise ValueError(
                f"{flag('ray_address')} must be a Ray address (host:port, ray://host:port or "
                f"auto), got {self.ray_address!r}"
            )
        check_number("sample_timeout_s", self.sample_timeout_s, float, lambda v: v > 0, "> 0")


DEFENDER_ENV = "sensor_game_v0"  # the defender command's default env


@dataclass
class TrainConfig:
    """Train one player of a registered env and score it against the analytic optimum.

    In a two-player env the other player is fixed (``--opponent``).
    """

    env: str = SPARSE_ENVS[0]
    """Registered env (a bad name lists the valid ones); the sparse attacker's default is its
    newest version, the older ones by name (sparse_attack_v0, sparse_attack_v1)."""
    task: str | None = None
    """Benchmark task (fdia_env.tasks.names()): train its scored player on its env exactly as
    the task builds it and score the run on it as python -m agents.bench score does; takes
    every --algo that fits the task's actions, --backend rllib and --resume (which keeps the
    run's task); excludes --env, --scenario, --env-kwargs and --opponent."""
    scenario: str | None = None
    """Scenario preset (default: the env's first: ch4-position, ch2-position, ch5-game)."""
    env_kwargs: dict[str, str] = field(default_factory=dict)
    """Extra env options as name value pairs (JSON values), e.g. --env-kwargs budget 4 horizon 8."""
    opponent: Literal["uniform", "equilibrium"] = "uniform"
    """Two-player envs: the fixed other player, the uniform mix or the LP equilibrium mix."""
    algo: str | None = None
    """PPO, MaskablePPO, A2C, DQN or SAC, where it fits the env (default: the env's first), or
    torch-ppo (every env: PPO with env, rollout buffer and policy on --device)."""
    num_envs: int | None = None
    """torch-ppo: members of the torch vector env stepped at once on --device (default 4096).
    MaskablePPO: train on the env's native vector env of this many members (default: one env,
    8 on the grid presets' sparse attack unless --n-steps is given; each rollout is num_envs x
    n_steps decisions). The other stable-baselines3 algorithms train on one env and reject it."""
    total_timesteps: int = 100_000
    """Environment steps to train for, in total across resumes."""
    eval_freq: int = 10_000
    """Steps between evaluations during training (0: none)."""
    eval_episodes: int = 10
    """Episodes per evaluation during training."""
    final_eval_episodes: int = 100
    """Episodes of the final evaluation (the printed table and scores.json)."""
    checkpoint_freq: int = 10_000
    """Steps between checkpoints (the final model is always saved)."""
    normalize_reward: bool | None = None
    """Train on rewards rescaled so that doing nothing is 0 and the reference 1 (evaluation
    stays on the raw rewards). Default: the scenario's (on for the grid presets)."""
    run: tyro.conf.OmitArgPrefixes[RunSettings] = field(default_factory=RunSettings)
    """Run folder, seeding and output."""
    hp: tyro.conf.OmitArgPrefixes[Hyperparameters] = field(default_factory=Hyperparameters)
    """Hyperparameters (None: the algorithm's default)."""
    agent: tyro.conf.Suppress[str] = "attacker"
    """Learning player, set by the command (attacker or defender)."""

    def __post_init__(self) -> None:
        check_choice("agent", self.agent, ("attacker", "defender"))
        check_choice("opponent", self.opponent, ("uniform", "equilibrium"))
        check_env_kwargs_format(self.env_kwargs)
        if self.num_envs is not None:
            check_number(
                "num_envs", self.num_envs, int, lambda v: 1 <= v <= MAX_NUM_ENVS,
                f"in [1, {MAX_NUM_ENVS}]",
            )  # fmt: skip
        for name, kind in (
            ("total_timesteps", _AT_LEAST_1),
            ("eval_freq", (int, lambda v: v >= 0, ">= 0 (0: no evaluations during training)")),
            ("eval_episodes", _AT_LEAST_1),
            ("final_eval_episodes", _AT_LEAST_1),
            ("checkpoint_freq", (int, lambda v: v >= 0, ">= 0 (0: only the final checkpoint)")),
        ):
            check_number(name, getattr(self, name), *kind)


@dataclass
class GameConfig:
    """Find an equilibrium of a two-player game by self-play with learned best responses.

    The exploitability of the current strategies is reported after every iteration.
    """

    method: Literal["psro", "fsp", "ibr", "selfplay"] = "psro"
    """psro (LP meta-solver), fsp (average of all best responses), ibr (latest best response),
    selfplay (--backend rllib: both players learning at once, scored by their average mix)."""
    env: str = "sensor_game_v0"
    """Registered two-player env."""
    task: str | None = None
    """Benchmark game task (fdia_env.tasks.names(), e.g. sensor-game/ch5-game-attacker-v0):
    play its game exactly as the task builds it, train both players, and score the task's
    player's final mix on the task as python -m agents.bench score does. Best responses
    default to exact (PSRO is then double oracle and reaches the game value); excludes --env,
    --scenario and --env-kwargs."""
    scenario: str | None = None
    """Scenario preset (default: the env's first, ch5-game)."""
    env_kwargs: dict[str, str] = field(default_factory=dict)
    """Extra env options as name value pairs (JSON values), e.g. --env-kwargs power 50."""
    algo: str | None = None
    """Best-response oracle: PPO, A2C or DQN (default: PPO), torch-ppo (on --device), or exact
    (the exact best response on the payoff matrix: nothing is learned)."""
    iterations: int | None = None
    """Iterations; each trains one attacker and one defender best response (default 8; with
    --task, PSRO and exact best responses: until the equilibrium is reached, double oracle's
    fixed point)."""
    steps_per_iteration: int = 3_000
    """Environment steps per best response."""
    final_eval_episodes: int = 1_000
    """Episodes of the final evaluation of each mixed strategy."""
    normalize_reward: bool | None = None
    """Train the best responses on rewards divided by the game value's size (evaluation stays
    on the raw rewards). Default: the scenario's (on for grid-ieee14)."""
    expected_rewards: bool | None = None
    """Pay each SB3 best response the expected reward over the other side's mix (the env
    played against every strategy of its support) instead of one sampled draw per episode.
    Default: the scenario's (on for grid-ieee14, :data:`GAME_EXPECTED_REWARDS`)."""
    run: tyro.conf.OmitArgPrefixes[RunSettings] = field(default_factory=RunSettings)
    """Run folder, seeding and output."""
    hp: tyro.conf.OmitArgPrefixes[Hyperparameters] = field(default_factory=Hyperparameters)
    """Hyperparameters of the learner (None: the algorithm's default)."""

    def __post_init__(self) -> None:
        check_choice("method", self.method, ("psro", "fsp", "ibr", "selfplay"))
        if self.expected_rewards is not None and not isinstance(self.expected_rewards, bool):
            raise TypeError(
                f"{flag('expected_rewards')} must be true or false, got {self.expected_rewards!r}"
            )
        check_env_kwargs_format(self.env_kwargs)
        for name in ("iterations", "steps_per_iteration", "final_eval_episodes"):
            if getattr(self, name) is not None:
                check_number(name, getattr(self, name), *_AT_LEAST_1)

    @property
    def n_iterations(self) -> int:
        """``--iterations``, else :data:`GAME_ITERATIONS`.

        A run that :attr:`converges` without ``--iterations`` runs to its fixed point instead.
        """
        return GAME_ITERATIONS if self.iterations is None else self.iterations

    @property
    def converges(self) -> bool:
        """Whether the run is a ``--task`` run of PSRO with exact best responses (double oracle).

        Such a run (``--task``'s default) iterates until the equilibrium is reached unless
        ``--iterations`` is given.
        """
        exact = self.algo is None or str(self.algo).strip().lower() == "exact"
        return self.task is not None and exact and self.method == "psro"


def _check_tuple(name: str, values: object, kind: type, ok: Callable[[float], bool], allowed: str):
    if not isinstance(values, tuple | list):
        raise TypeError(f"{flag(name)} must be a list of values, got {values!r}")
    for v in values:
        check_number(name, v, kind, ok, allowed)


@dataclass
class SweepConfig:
    """A Ray Tune sweep of RLlib PPO runs over seeds, scenarios and hyperparameters.

    Every combination of --seeds, --scenarios, --learning-rates and --ent-coefs is one trial:
    ``--agent attacker|defender`` trains that player of the view (the other fixed, as
    ``--opponent``), ``--agent both`` both players of a game at once (self-play). Each trial is
    scored by agents.evaluate against the analytic reference; the sweep writes one results table
    (results.csv, results.json) in its run folder.
    """

    env: str = SPARSE_ENVS[0]
    """Registered env (a bad name lists the valid ones)."""
    agent: Literal["attacker", "defender", "both"] = "attacker"
    """The learning player(s); both: self-play of a two-player game."""
    scenarios: tuple[str, ...] = ()
    """Scenario presets to sweep (default: the env's first)."""
    seeds: tuple[int, ...] = (0, 1)
    """Seeds to sweep."""
    learning_rates: tuple[float, ...] = ()
    """Learning rates to sweep (default: --learning-rate or the RLlib default)."""
    ent_coefs: tuple[float, ...] = ()
    """Entropy coefficients to sweep (default: --ent-coef or the RLlib default)."""
    env_kwargs: dict[str, str] = field(default_factory=dict)
    """Extra env options as name value pairs (JSON values), for every trial."""
    opponent: Literal["uniform", "equilibrium"] = "uniform"
    """Two-player envs with one learning player: the fixed other player."""
    total_timesteps: int = 20_000
    """Environment steps per trial."""
    final_eval_episodes: int = 100
    """Episodes of each trial's final evaluation."""
    max_concurrent_trials: int | None = None
    """Trials running at once (default: as many as the CPUs allow)."""
    run: tyro.conf.OmitArgPrefixes[RunSettings] = field(
        default_factory=lambda: RunSettings(backend="rllib")
    )
    """Run folder, seeding and Ray settings (each trial samples in its own process unless
    --num-env-runners is given)."""
    hp: tyro.conf.OmitArgPrefixes[Hyperparameters] = field(default_factory=Hyperparameters)
    """Hyperparameters of every trial (None: the RLlib default)."""

    def __post_init__(self) -> None:
        check_choice("agent", self.agent, ("attacker", "defender", "both"))
        check_choice("opponent", self.opponent, ("uniform", "equilibrium"))
        if self.run.backend != "rllib":
            raise ValueError(f"{flag('backend')}: train.py sweep runs on rllib only")
        check_env_kwargs_format(self.env_kwargs)
        if not isinstance(self.scenarios, tuple | list) or not all(
            isinstance(s, str) for s in self.scenarios
        ):
            raise TypeError(f"{flag('scenarios')} must be a list of scenario names")
        _check_tuple("seeds", self.seeds, int, lambda v: 0 <= v <= MAX_SEED, f"in [0, {MAX_SEED}]")
        if not self.seeds:
            raise ValueError(f"{flag('seeds')} needs at least one seed")
        _check_tuple("learning_rates", self.learning_rates, float, lambda v: v > 0, "> 0")
        _check_tuple("ent_coefs", self.ent_coefs, float, lambda v: v >= 0, ">= 0")
        for name in ("total_timesteps", "final_eval_episodes"):
            check_number(name, getattr(self, name), *_AT_LEAST_1)
        if self.max_concurrent_trials is not None:
            check_number("max_concurrent_trials", self.max_concurrent_trials, *_AT_LEAST_1)
