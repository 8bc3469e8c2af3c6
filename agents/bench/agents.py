"""Load the agent a benchmark task is scored on, from whatever the user has.

:func:`load_agent` accepts, as ``agent``:

- a ``train.py`` run folder (stable-baselines3, torch-ppo or RLlib backend: the folder's
  ``config.json`` says which, and which env and options the agent was trained on); a
  ``train.py game`` run folder, on a game task, is the final mix of the task's player (its
  ``scores.json``'s ``x`` or ``y``);
- a model file: a stable-baselines3 model description ``.json`` (tensors-only, written by
  ``train.py``), a torch-ppo policy ``.json`` (:func:`agents.torch_ppo.save_policy`), or a
  stable-baselines3 ``.zip``, which is unpickled when loaded and so is refused unless the user
  trusts it (``trust_checkpoint=True``, ``--trust-checkpoint``);
- an RLlib run's state (``rllib_state.json`` of a run folder; tensors only, never RLlib's own
  pickled ``checkpoint/`` folder);
- ``"module:function"``: a Python callable that returns an action for an observation (it is
  given ``action_masks=`` too when it takes that keyword), or that names an object with SB3's
  ``predict``;
- ``"random"``: uniformly random legal actions.

A checkpoint that records the env it was trained on (a run folder's ``config.json``) must have
been trained on the task's env id and options; one whose spaces differ from the task env's is
refused too. A ``train.py --task`` run records its task's name (``resolved.task``) and is scored
on that task only, its recorded options checked against the task's. Every error names the
parameter (``agent``, ``algo`` or ``trust_checkpoint``).
"""

from __future__ import annotations

import importlib
import inspect
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym

from fdia_env.envs.policy import MaskedPolicyBase

CALLABLE = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")
SB3_FORMAT = "fdia_env-sb3-state-v1"
TORCH_PPO_FORMAT = "fdia_env-torch-ppo-v1"


@dataclass(frozen=True)
class LoadedAgent:
    """An agent ready to play: a policy with stable-baselines3's ``predict``.

    Attributes:
        policy: The policy (``predict(obs, deterministic=..., action_masks=...)``), or the
            string ``"random"``.
        kind: ``"random"``, ``"callable"``, ``"sb3"``, ``"sb3-zip"``, ``"torch-ppo"``,
            ``"rllib"`` or ``"game"`` (a game run's final mix).
        source: What the user gave.
        description: One line for the report (kind, algorithm, steps trained).
    """

    policy: Any
    kind: str
    source: str
    description: str


class CallablePolicy(MaskedPolicyBase):
    """A function ``f(observation) -> action`` behind SB3's ``predict``.

    ``f`` receives ``action_masks=`` as well when its signature takes that keyword (or
    ``**kwargs``) and the env has masks.
    """

    def __init__(self, function: Any, name: str) -> None:
        self.function = function
        self.name = name
        try:
            params = inspect.signature(function).parameters
        except (TypeError, ValueError):
            params = {}
        self.takes_masks = "action_masks" in params or any(
            p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()
        )

    def act(self, observation: Any, deterministic: bool = False, action_masks: Any = None) -> Any:
        """The function's action for ``observation`` (``deterministic`` is not passed on)."""
        if self.takes_masks:
            return self.function(observation, action_masks=action_masks)
        return self.function(observation)


# ------------------------------------------------------------------------------ task checks


def _plain(value: Any) -> Any:
    """A value as JSON would give it back (tuples as lists), for comparisons."""
    return json.loads(json.dumps(value, default=str))


def _defaults(task: Any) -> dict[str, Any]:
    """The task env constructor's default options (the PettingZoo module's ``parallel_env``)."""
    if not task.module:
        return {}
    name = task.module if "." in task.module else f"fdia_env.{task.module}"
    try:
        params = inspect.signature(importlib.import_module(name).parallel_env).parameters
    except (ImportError, AttributeError, TypeError, ValueError):
        return {}
    return {
        k: p.default
        for k, p in params.items()
        if p.default is not inspect.Parameter.empty and p.default is not None
    }


# Versions of one env whose differences are only default options (the sparse attack's: the
# action format and decision order, each version's Version History): a run trained on one
# plays a task pinned to another when both build the same env.
_DEFAULTS_ONLY_VERSIONS = re.compile(r"(fdia_env/SparseAttack|sparse_attack)[-_]v\d+")
_VERSIONED_DEFAULTS = ("action", "order")


def _built_as(env_id: str, env_kwargs: Any) -> Any:
    """What defines an env's interface: its class, attack format, order and the player's spaces."""
    from fdia_env.registration import GYM_IDS, get_env

    module, agent = GYM_IDS[env_id] if env_id in GYM_IDS else (get_env(env_id).module, "attacker")
    env = importlib.import_module(module).parallel_env(**dict(env_kwargs))
    try:
        inner = getattr(env, "inner", env)
        return (
            type(env).__name__,
            inner.attack.format,
            getattr(env, "order", None),
            env.observation_space(agent),
            env.action_space(agent),
        )
    finally:
        env.close()


def _same_env(env_id: str, env_kwargs: Any, task: Any) -> bool:
    """Whether ``env_id`` is another version of the task's env that builds the same env."""
    if not (
        _DEFAULTS_ONLY_VERSIONS.fullmatch(str(env_id))
        and _DEFAULTS_ONLY_VERSIONS.fullmatch(task.env_id)
    ):
        return False
    try:
        return _built_as(env_id, env_kwargs) == _built_as(task.env_id, task.env_kwargs)
    except (KeyError, TypeError, ValueError):
        return False  # options the other version does not take: not the same env


def check_trained_on(
    source: str,
    env_id: str | None,
    env_kwargs: dict[str, Any],
    task: Any,
    config: Path | None = None,
) -> None:
    """Raise unless a checkpoint trained on ``env_id`` with ``env_kwargs`` fits ``task``.

    An option given on one side only is compared with the env's default; an option left at
    None (the scenario's default) on either side is not compared, except that with ``config``
    (the run's ``config.json``, which records every option the run was trained with) an
    option the task sets and the run leaves at None is an error. Another version of the
    sparse attack than the task's is accepted where, with the run's and the task's options,
    both build the same env (up to 16 sensors its versions are one env; above, their default
    formats differ).

    Raises:
        ValueError: Naming ``agent``, the env id or the options that differ (and ``config``
            and the key for an option the run does not record).
    """
    other_version = env_id is not None and env_id != task.env_id
    if other_version and not _same_env(env_id, env_kwargs, task):
        raise ValueError(
            f"agent {source} was trained on {env_id}, but task {task.name} is played on "
            f"{task.env_id}: score it on a task of its env"
        )
    defaults = _defaults(task)
    theirs, ours = _plain(dict(env_kwargs)), _plain(dict(task.env_kwargs))
    differ = []
    for key in sorted(set(theirs) | set(ours)):
        if other_version and key in _VERSIONED_DEFAULTS:
            continue  # compared as built: the versions' defaults differ, the envs do not
        a = theirs.get(key, _plain(defaults.get(key)))
        b = ours.get(key, _plain(defaults.get(key)))
        if config is not None and a is None and b is not None:
            raise ValueError(
                f"agent {source}: {config} records no value for resolved.env_kwargs.{key} "
                f"(task {task.name} plays {key}={b!r}): the run's training options cannot be "
                "established"
            )
        if a is None or b is None or a == b:
            continue
        differ.append(f"{key}={a!r} (task: {b!r})")
    if differ:
        raise ValueError(
            f"agent {source} was trained with other env options than task {task.name}: "
            + ", ".join(differ)
        )


def check_spaces(source: str, observation_space: Any, action_space: Any, env: gym.Env) -> None:
    """Raise unless the policy's spaces are the task env's.

    Raises:
        ValueError: Naming ``agent`` and both spaces.
    """
    for what, theirs, ours in (
        ("observation", observation_space, env.observation_space),
        ("action", action_space, env.action_space),
    ):
        if theirs is not None and theirs != ours:
            raise ValueError(
                f"agent {source} has the {what} space {theirs}, the task env {ours}: it was "
                "trained on another task"
            )


# ------------------------------------------------------------------------------ loaders


def _callable(source: str, env: gym.Env) -> LoadedAgent:
    module_name, _, attr = source.partition(":")
    try:
        obj: Any = importlib.import_module(module_name)
    except ImportError as exc:
        raise ValueError(
            f"agent {source!r}: cannot import module {module_name!r} ({exc}); give "
            "'module:function' with the module on the Python path, a run folder or a model file"
        ) from None
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise ValueError(f"agent {source!r}: module {module_name!r} has no {attr!r}")
        obj = getattr(obj, part)
    if callable(getattr(obj, "predict", None)):
        return LoadedAgent(obj, "callable", source, f"{source} (a policy with predict)")
    if not callable(obj):
        raise ValueError(f"agent {source!r}: {attr} is neither callable nor a policy")
    return LoadedAgent(CallablePolicy(obj, source), "callable", source, f"{source} (a function)")


def _read_json(path: Path, what: str) -> dict[str, Any]:
    from agents.checkpoint import read_json

    return read_json(path, what)


def _sb3(path: Path, root: Path, env: gym.Env, source: str, algo: str | None) -> LoadedAgent:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from agents.checkpoint import load_model

    vec = DummyVecEnv([lambda: env])
    model = load_model(path, vec, root, algo=algo)
    meta = _read_json(path, "model description")
    return LoadedAgent(
        model,
        "sb3",
        source,
        f"stable-baselines3 {meta['algo']}, {int(meta.get('num_timesteps', 0)):,} steps",
    )


def _sb3_zip(path: Path, env: gym.Env, source: str, algo: str | None, trusted: bool) -> LoadedAgent:
    from agents.checkpoint import UntrustedCheckpointError, load_sb3_zip

    try:
        model = load_sb3_zip(path, algo, trusted)
    except UntrustedCheckpointError as exc:
        raise UntrustedCheckpointError(
            f"agent {source}: {exc} (trust_checkpoint=True, --trust-checkpoint)"
        ) from None
    except ValueError as exc:
        raise ValueError(f"agent {source}: {exc}") from None
    check_spaces(source, model.observation_space, model.action_space, env)
    return LoadedAgent(
        model, "sb3-zip", source, f"stable-baselines3 {algo} (.zip), {model.num_timesteps:,} steps"
    )


def _torch_ppo(path: Path, root: Path, env: gym.Env, source: str) -> LoadedAgent:
    from gymnasium import spaces

    from agents.torch_ppo import PolicySpec, load_policy

    policy = load_policy(path, root)
    meta = _read_json(path, "model description")
    try:
        expected = PolicySpec.of(env.observation_space, env.action_space)
    except ValueError:
        expected = None
    got = policy.spec
    if expected is not None and (
        (got.obs_dim, got.kind, got.n, got.low, got.high)
        != (expected.obs_dim, expected.kind, expected.n, expected.low, expected.high)
    ):
        raise ValueError(
            f"agent {source} is a torch-ppo policy for {got.obs_dim} observations and "
            f"{got.n} {got.kind} actions; the task env has {expected.obs_dim} and "
            f"{expected.n} {expected.kind}: it was trained on another task"
        )
    if isinstance(env.action_space, spaces.Discrete) and expected is None:
        raise ValueError(f"agent {source}: the task env's actions do not fit torch-ppo")
    steps = int(meta.get("num_timesteps", 0))
    return LoadedAgent(policy, "torch-ppo", source, f"torch-ppo, {steps:,} steps")


def _rllib(run_dir: Path, env: gym.Env, config: dict[str, Any], source: str) -> LoadedAgent:
    from agents.rllib import require_ray

    require_ray()
    from ray.rllib.core import DEFAULT_MODULE_ID

    from agents.config import Hyperparameters
    from agents.rllib.config import ppo_config
    from agents.rllib.envs import TASK_ENV, is_masked, make_view
    from agents.rllib.policy import RLlibPolicy
    from agents.rllib.state import read_state

    resolved = config.get("resolved", {})
    gym_id, env_kwargs = resolved.get("env"), dict(resolved.get("env_kwargs", {}))
    if resolved.get("task") is not None:  # a --task run: the task's env (its options objects)
        gym_id, env_kwargs = TASK_ENV, {"task": resolved["task"]}
    net = resolved.get("hyperparameters", {}).get("net_arch")
    meta, payload = read_state(run_dir)
    key = f"rl_module/{DEFAULT_MODULE_ID}"
    if key not in payload["state_dicts"]:
        raise ValueError(
            f"agent {source}: its RLlib state holds the modules {meta['modules']}, not the "
            "single-agent module of a train.py attacker/defender run"
        )
    hp = Hyperparameters(net_arch=tuple(net)) if net else None
    rl_config = ppo_config(gym_id, env_kwargs, hp=hp, total_timesteps=1)
    with make_view(gym_id, env_kwargs) as view:
        spec = rl_config.get_rl_module_spec(env=view, inference_only=False)
        masked = is_masked(view.observation_space)
    module = spec.build()
    try:
        module.load_state_dict(payload["state_dicts"][key], strict=True)
    except (RuntimeError, TypeError) as exc:
        first = str(exc).strip().splitlines()[0]
        raise ValueError(
            f"agent {source}: its RLlib state does not fit the network: {first}"
        ) from None
    module.eval()
    steps = int(meta.get("timesteps", 0))
    return LoadedAgent(
        RLlibPolicy(module, env.action_space, masked, seed=0),
        "rllib",
        source,
        f"RLlib PPO, {steps:,} steps",
    )


def run_config(path: Path, source: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """A run's ``config.json`` and its ``resolved`` entry, with the training options checked.

    The options a run was trained with must be established before it is scored: ``resolved``
    must be an object, its env id (``gym_id``; ``env`` for an RLlib run) a non-empty string
    and its ``env_kwargs`` an object without null values (train.py writes every option).

    Raises:
        ValueError: Naming ``agent``, ``path`` and the key that is missing or null.
    """
    config = _read_json(path, "run config")
    resolved = config.get("resolved")
    lost = "the run's training options cannot be established (score an intact train.py run)"
    if not isinstance(resolved, dict):
        raise ValueError(
            f"agent {source}: {path} has no 'resolved' object (got {resolved!r}): {lost}"
        )
    key = "env" if resolved.get("backend") == "rllib" else "gym_id"
    env_id = resolved.get(key)
    if not isinstance(env_id, str) or not env_id:
        raise ValueError(
            f"agent {source}: {path}: resolved.{key} is {env_id!r}, not an env id: {lost}"
        )
    env_kwargs = resolved.get("env_kwargs")
    if not isinstance(env_kwargs, dict):
        raise ValueError(
            f"agent {source}: {path}: resolved.env_kwargs is {env_kwargs!r}, not an object: {lost}"
        )
    for name, value in env_kwargs.items():
        if value is None:
            raise ValueError(f"agent {source}: {path}: resolved.env_kwargs.{name} is null: {lost}")
    return config, resolved


def _task_options_differ(recorded: dict[str, Any], task: Any) -> list[str]:
    """The options a ``--task`` run records otherwise than ``task`` sets them.

    An option whose value is an object (a scenario, an opponent policy) is recorded as its
    text and compared by its presence only: the task's name fixes it.
    """
    ours = dict(task.env_kwargs)
    differ = sorted(set(recorded) ^ set(ours))
    for key in sorted(set(recorded) & set(ours)):
        try:
            value = json.loads(json.dumps(ours[key]))
        except (TypeError, ValueError):
            continue
        if recorded[key] != value:
            differ.append(key)
    return differ


def _check_run(path: Path, source: str, task: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """:func:`run_config`, then :func:`check_trained_on` with the run's env and options."""
    config, resolved = run_config(path, source)
    env_id = resolved["env" if resolved.get("backend") == "rllib" else "gym_id"]
    trained_task = resolved.get("task")
    if trained_task is not None:  # a train.py --task run: built as its task builds its env
        if trained_task != task.name or env_id != task.env_id:
            raise ValueError(
                f"agent {source} was trained on task {trained_task!r} ({env_id}), not on task "
                f"{task.name} ({task.env_id}): score it on its own task"
            )
        differ = _task_options_differ(resolved["env_kwargs"], task)
        if differ:
            raise ValueError(
                f"agent {source}: {path} records other env options for task {task.name} than "
                f"the task's ({', '.join(differ)}): the run's training options cannot be "
                "established"
            )
        return config, resolved
    check_trained_on(source, env_id, resolved["env_kwargs"], task, config=path)
    return config, resolved


def _game_env_id(config: dict[str, Any], task: Any) -> str | None:
    """The Gymnasium id of the view of the task's player in a game run's env (None: none)."""
    from fdia_env.registration import get_env

    name = config.get("config", {}).get("env") if isinstance(config.get("config"), dict) else None
    try:
        return get_env(name).views.get(task.player) if isinstance(name, str) else None
    except (KeyError, ValueError):
        return None


def _game_run(folder: Path, env: gym.Env, task: Any, source: str) -> LoadedAgent:
    """The final mix of the task's player in a ``train.py game`` run (its ``scores.json``).

    A game run trains both players of one game, so it scores on the game task of either
    player whose env and options it was trained on: a ``--task`` run on its own task and the
    other player's task of the same game (both recorded options equal), a run without ``--task``
    where :func:`check_trained_on` accepts its env's view of that player and its options.
    """
    import numpy as np

    from baselines.game import MixedStrategyPolicy, TypedMixedStrategyPolicy

    config_path = folder / "config.json"
    config = _read_json(config_path, "run config")
    if not getattr(task, "is_game", False):
        raise ValueError(
            f"agent {source} is a train.py game run (a mixed strategy for each player of a "
            f"game); task {task.name} is not a game: score the run on a game task"
        )
    resolved = config.get("resolved")
    env_kwargs = resolved.get("env_kwargs") if isinstance(resolved, dict) else None
    if not isinstance(resolved, dict) or not isinstance(env_kwargs, dict):
        raise ValueError(
            f"agent {source}: {config_path} records no resolved env options: the run's "
            "training options cannot be established (score an intact train.py run)"
        )
    trained_task = resolved.get("task")
    env_id = _game_env_id(config, task)
    if isinstance(trained_task, str):
        differ = _task_options_differ(env_kwargs, task)
        if differ or env_id != task.env_id:
            raise ValueError(
                f"agent {source} was trained on task {trained_task!r}, whose game is not task "
                f"{task.name}'s: score it on its own task (or the other player's of its game)"
            )
    elif env_id is None:
        raise ValueError(
            f"agent {source}: the game run's env has no {task.player} view: it was trained on "
            f"another game than task {task.name}"
        )
    else:
        check_trained_on(source, env_id, env_kwargs, task, config=config_path)
    scores_path = folder / "scores.json"
    if not scores_path.is_file():
        raise ValueError(
            f"agent {source}: the game run holds no scores.json (no iteration finished; "
            "resume it with train.py game --resume)"
        )
    scores = _read_json(scores_path, "run scores")
    key = "y" if task.player == "attacker" else "x"
    try:
        probs = np.asarray(scores.get(key), dtype=np.float64)
    except (TypeError, ValueError):
        probs = np.zeros(0)
    n = int(getattr(env.action_space, "n", -1))
    if probs.ndim not in (1, 2) or probs.shape[-1] != n or not np.all(np.isfinite(probs)):
        raise ValueError(
            f"agent {source}: {scores_path} holds no final mix of the {task.player} over the "
            f"task env's {n} actions ({key!r} is {scores.get(key)!r:.80}): it was trained on "
            "another game"
        )
    try:
        policy = (TypedMixedStrategyPolicy if probs.ndim == 2 else MixedStrategyPolicy)(
            probs, seed=0
        )
    except ValueError as exc:
        raise ValueError(
            f"agent {source}: {scores_path}: {key!r} is no mixed strategy ({exc})"
        ) from None
    support = int(np.count_nonzero(probs.max(axis=0) if probs.ndim == 2 else probs))
    what = f"{scores.get('method', '?')} with {resolved.get('algo', '?')} best responses"
    return LoadedAgent(
        policy,
        "game",
        source,
        f"train.py game run ({what}, {scores.get('iterations', '?')} iterations): the "
        f"{task.player}'s final mix, {support} of {n} actions",
    )


def _run_folder(
    folder: Path, env: gym.Env, task: Any, source: str, algo: str | None, trusted: bool
) -> LoadedAgent:
    config_path = folder / "config.json"
    config = _read_json(config_path, "run config")
    if config.get("command") == "game":
        return _game_run(folder, env, task, source)
    if config.get("command") not in ("attacker", "defender"):
        raise ValueError(
            f"agent {source} is a train.py {config.get('command')!r} run; score an attacker, "
            "defender or game run"
        )
    config, resolved = _check_run(config_path, source, task)
    if resolved.get("backend") == "rllib":
        if not (folder / "rllib_state.json").is_file():
            raise ValueError(f"agent {source}: the RLlib run holds no rllib_state.json")
        return _rllib(folder, env, config, source)
    model = folder / "model.json"
    if not model.is_file():
        raise ValueError(
            f"agent {source}: the run folder holds no model.json (training did not finish; "
            "resume it with train.py --resume)"
        )
    run_algo = resolved.get("algo")
    if algo is not None and algo != run_algo:
        raise ValueError(f"algo {algo!r} was given, but the run {source} trained {run_algo}")
    if resolved.get("backend") == "torch":
        return _torch_ppo(model, folder, env, source)
    return _sb3(model, folder, env, source, run_algo)


def _model_file(
    path: Path, env: gym.Env, task: Any, source: str, algo: str | None, trusted: bool
) -> LoadedAgent:
    folder = path.parent
    config_path = folder / "config.json"
    if config_path.is_file():  # a model of a run folder: check what the run was trained on
        _check_run(config_path, source, task)
    if path.suffix == ".zip":
        return _sb3_zip(path, env, source, algo, trusted)
    if path.suffix != ".json":
        raise ValueError(
            f"agent {source}: expected a run folder, a model .json (with its .pt), an RLlib "
            "rllib_state.json, a stable-baselines3 .zip or 'module:function'"
        )
    meta = _read_json(path, "model description")
    fmt = meta.get("format")
    if fmt == SB3_FORMAT:
        return _sb3(path, folder, env, source, algo)
    if fmt == TORCH_PPO_FORMAT:
        return _torch_ppo(path, folder, env, source)
    if fmt == "fdia_env-rllib-state-v1":
        config = _read_json(config_path, "run config") if config_path.is_file() else None
        if config is None:
            raise ValueError(f"agent {source}: an RLlib state needs its run folder's config.json")
        return _rllib(folder, env, config, source)
    raise ValueError(f"agent {source}: {path.name} is no model description (format {fmt!r})")


def load_agent(
    agent: str | Path,
    task: Any,
    env: gym.Env,
    algo: str | None = None,
    trust_checkpoint: bool = False,
) -> LoadedAgent:
    """The policy ``agent`` names, checked against ``task`` (see the module docstring).

    Args:
        agent: A run folder, a model file, ``"module:function"`` or ``"random"``.
        task: The :class:`fdia_env.tasks.Task` it will be scored on.
        env: The task's env (for the spaces and SB3's model rebuild).
        algo: The stable-baselines3 algorithm of a bare ``.zip`` (checked against a run's).
        trust_checkpoint: Allow a stable-baselines3 ``.zip``, which is unpickled and can run
            code: only for files the user made or trusts.

    Raises:
        ValueError: For an agent that does not exist or cannot be read, one trained on another
            task, or a ``.zip`` without ``algo``.
        agents.checkpoint.UntrustedCheckpointError: For a ``.zip`` without
            ``trust_checkpoint`` (a ValueError too).
    """
    source = str(agent)
    if source == "random":
        return LoadedAgent("random", "random", source, "uniformly random legal actions")
    path = Path(source)
    if not path.exists():
        if CALLABLE.match(source):
            return _callable(source, env)
        raise ValueError(
            f"agent {source!r} is neither an existing run folder or model file nor "
            "'module:function' nor 'random'"
        )
    if path.is_dir():
        if (path / "config.json").is_file():
            return _run_folder(path, env, task, source, algo, trust_checkpoint)
        raise ValueError(f"agent {source}: the folder holds no config.json (no train.py run)")
    return _model_file(path, env, task, source, algo, trust_checkpoint)
