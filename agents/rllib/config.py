"""The RLlib PPO config for fdia_env: the settings its short episodes need, and why.

:func:`ppo_config` builds a ``PPOConfig`` (new API stack) for any env of
:mod:`agents.rllib.envs`, multi-agent (a module: one RL module per player) or single-agent (a
Gymnasium view). What it sets beyond RLlib's defaults:

- ``episodes_to_numpy=False``: RLlib converts every finished episode to numpy at the env step
  that ends it; with the one-step episodes of the sensor game that is every step;
- one torch thread in every env runner and in the driver (these networks are tiny);
- ``num_envs_per_env_runner=8``: one batched forward pass serves 8 envs;
- a train batch of 1,000 steps, minibatches of 128, 10 epochs, 64×64 networks, ``gamma=1``
  (the windows are a few steps long): RLlib's 4,000 × 30 epochs on 256×256 networks spends
  far more time per step for these bandit-like games;
- entropy coefficient 0.1 and a learning rate decaying linearly to 0 over the run (when its
  length is known): with SB3's 0.01 and a constant rate the sparse attacker of seed 1 settled
  on a plan worth 89.6 % of EXS; with these, 100 % on seeds 0-3;
- RLlib's ``ActionMaskingTorchRLModule`` for every player with illegal actions (their
  observations are ``{"observations", "action_mask"}``, :mod:`agents.rllib.envs`), so no
  illegal action is ever sampled;
- per-agent episode returns as ``result["agent_returns"]`` (``episode_return_mean`` sums the
  players: 0 in every zero-sum iteration), and :class:`ZeroStepsSampled` raised when an
  iteration sampled nothing (RLlib only logs its sample timeout).

Measured figures are in ``docs/guide/rllib.md`` and ``benchmarks/rllib.py``.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping
from typing import Any

from agents.config import HYPERPARAMETERS, Hyperparameters, check_number, flag
from agents.rllib import ZeroStepsSampled
from agents.rllib.envs import (
    MODULES,
    TASK_ENV,
    is_masked,
    make_multi_agent,
    make_view,
    register_envs,
)

logger = logging.getLogger(__name__)

# The project's PPO defaults under RLlib; n_steps is the train batch of one iteration (all env
# runners together), batch_size the SGD minibatch.
RLLIB_DEFAULTS: dict[str, Any] = {
    "learning_rate": 1e-3,
    "gamma": 1.0,
    "n_steps": 1_000,
    "batch_size": 128,
    "n_epochs": 10,
    "ent_coef": 0.1,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "lr_schedule": "linear",
    "net_arch": (64, 64),
}
ENVS_PER_ENV_RUNNER = 8
SAMPLE_TIMEOUT_S = 600.0


def rllib_hyperparameters(hp: Hyperparameters | None = None) -> dict[str, Any]:
    """Every PPO hyperparameter with the value used under RLlib (for config.json).

    Raises:
        ValueError: For a hyperparameter of another algorithm (DQN, SAC), or a minibatch larger
            than the train batch.
    """
    values = dict(RLLIB_DEFAULTS)
    hp = hp or Hyperparameters()
    for name in HYPERPARAMETERS:
        given = getattr(hp, name)
        if given is None:
            continue
        if name not in values:
            raise ValueError(
                f"{flag(name)} does not apply to RLlib PPO; it takes: "
                + ", ".join(n.replace("_", "-") for n in RLLIB_DEFAULTS)
            )
        values[name] = given
    for name in ("n_steps", "batch_size"):
        check_number(name, values[name], int, lambda v: v >= 2, ">= 2 under RLlib PPO")
    if values["batch_size"] > values["n_steps"]:
        raise ValueError(
            f"{flag('batch_size')} ({values['batch_size']}) must be <= {flag('n_steps')} "
            f"({values['n_steps']}), the train batch of one RLlib iteration"
        )
    values["net_arch"] = list(values["net_arch"])
    return values


def one_torch_thread(**kwargs: Any) -> None:
    """``on_environment_created`` callback: one torch thread in each env runner."""
    import torch

    torch.set_num_threads(1)


def agent_returns(result: Mapping[str, Any]) -> dict[str, float]:
    """Mean episode return of each player in one ``Algorithm.train()`` result.

    A single-agent env's player is named by the view (``"attacker"`` or ``"defender"`` in
    ``result["agent_returns"]`` when :func:`report_agent_returns` ran); without episodes in the
    window the dict is empty.
    """
    if "agent_returns" in result:
        return dict(result["agent_returns"])
    runners = result.get("env_runners", {})
    per_agent = runners.get("agent_episode_returns_mean") or {}
    out = {str(k): float(v) for k, v in per_agent.items()}
    if not out and "episode_return_mean" in runners:
        out["default_agent"] = float(runners["episode_return_mean"])
    return out


def steps_sampled(result: Mapping[str, Any]) -> int:
    """Env steps sampled in one iteration (0 when the sampling timed out)."""
    return int(result.get("env_runners", {}).get("num_env_steps_sampled", 0) or 0)


class _Report:
    """``on_train_result`` callback: per-agent returns, and the zero-step check."""

    def __init__(self, single_agent: str | None, timeout: float | None) -> None:
        self.single_agent = single_agent
        self.timeout = timeout

    def __call__(self, *, algorithm: Any = None, result: dict, **kwargs: Any) -> None:
        returns = agent_returns({k: v for k, v in result.items() if k != "agent_returns"})
        if self.single_agent is not None and "default_agent" in returns:
            returns = {self.single_agent: returns.pop("default_agent")}
        result["agent_returns"] = returns
        if steps_sampled(result) == 0:
            msg = (
                f"iteration {result.get('training_iteration')} sampled 0 env steps: the env "
                f"runners returned nothing within sample_timeout_s={self.timeout} s (they may "
                "have failed, or be too slow for the train batch: see the Ray worker logs); "
                "raise --sample-timeout-s, lower --n-steps or use fewer env runners than CPUs"
            )
            logger.error(msg)
            raise ZeroStepsSampled(msg)


def ppo_config(
    env: str,
    env_config: Mapping[str, Any] | None = None,
    *,
    hp: Hyperparameters | None = None,
    num_env_runners: int = 0,
    envs_per_env_runner: int = ENVS_PER_ENV_RUNNER,
    seed: int = 0,
    total_timesteps: int | None = None,
    train_agents: Iterable[str] | None = None,
    sample_timeout_s: float | None = SAMPLE_TIMEOUT_S,
    fast: bool = True,
) -> Any:
    """The ``PPOConfig`` of ``env`` (a name of :func:`agents.rllib.envs.register_envs`).

    Args:
        env: A module (multi-agent: one RL module per player, named after it), a Gymnasium
            id (single-agent) or :data:`~agents.rllib.envs.TASK_ENV` (a benchmark task's env).
        env_config: The env kwargs (``scenario``, ...; a view also takes ``opponent``;
            ``{"task": NAME}`` for a task's env).
        hp: Hyperparameters (None fields: :data:`RLLIB_DEFAULTS`).
        num_env_runners: Remote env runners (0: sample in the driver process).
        envs_per_env_runner: Envs stepped together by each env runner.
        seed: RLlib's seed (networks, env runners' env seeds).
        total_timesteps: Where the default linear learning-rate schedule reaches 0; without
            it the default schedule is constant (an explicit ``lr_schedule="linear"`` then
            raises).
        train_agents: Multi-agent: the players that learn (default: all).
        sample_timeout_s: Seconds an iteration waits for the remote env runners.
        fast: False keeps RLlib's sampler, network and training-batch defaults (the reference
            of ``benchmarks/rllib.py``); masking, spaces, metrics and ``lr``, ``gamma``,
            ``lambda_``, ``clip_param``, ``entropy_coeff`` are set either way.

    Raises:
        ValueError: For an unknown env, a bad count or hyperparameter, or a linear schedule
            without ``total_timesteps``.
    """
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec
    from ray.rllib.examples.rl_modules.classes.action_masking_rlm import (
        ActionMaskingTorchRLModule,
    )

    names = register_envs()
    if env not in names:
        raise ValueError(f"env must be one of {', '.join(names)}, got {env!r}")
    check_number("num_env_runners", num_env_runners, int, lambda v: v >= 0, ">= 0")
    check_number("envs_per_env_runner", envs_per_env_runner, int, lambda v: v >= 1, ">= 1")
    if sample_timeout_s is not None:
        check_number("sample_timeout_s", sample_timeout_s, float, lambda v: v > 0, "> 0")
    values = rllib_hyperparameters(hp)
    env_config = dict(env_config or {})
    model = DefaultModelConfig(fcnet_hiddens=values["net_arch"]) if fast else DefaultModelConfig()

    def spec(obs_space: Any) -> RLModuleSpec:
        if is_masked(obs_space):
            return RLModuleSpec(module_class=ActionMaskingTorchRLModule, model_config=model)
        return RLModuleSpec(model_config=model)

    config = PPOConfig().environment(env, env_config=env_config)
    single_agent = None
    if env in MODULES:
        probe = make_multi_agent(env, env_config)
        players = list(probe.possible_agents)
        specs = {a: spec(probe.observation_spaces[a]) for a in players}
        probe.close()
        train = players if train_agents is None else list(train_agents)
        unknown = [a for a in train if a not in players]
        if unknown or not train:
            raise ValueError(f"train_agents must be players of {env} ({players}), got {train}")
        config = config.multi_agent(
            policies=set(players),
            policy_mapping_fn=_same_id,
            policies_to_train=train,
        ).rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs=specs))
    else:
        with make_view(env, env_config) as probe:
            config = config.rl_module(rl_module_spec=spec(probe.observation_space))
            single_agent = getattr(probe.unwrapped, "agent", None)
        if env == TASK_ENV:  # the system family's env names no player
            from fdia_env.tasks import get as get_task

            single_agent = get_task(env_config["task"]).player
    if train_agents is not None and env not in MODULES:
        raise ValueError("train_agents applies to multi-agent envs (a module name) only")

    lr: Any = values["learning_rate"]
    if values["lr_schedule"] == "linear" and total_timesteps is not None:
        lr = [[0, lr], [int(total_timesteps), 0.0]]
    elif values["lr_schedule"] == "linear" and hp is not None and hp.lr_schedule == "linear":
        raise ValueError("lr_schedule linear needs total_timesteps (the step where lr is 0)")
    training = {
        "lr": lr,
        "gamma": values["gamma"],
        "lambda_": values["gae_lambda"],
        "clip_param": values["clip_range"],
        "entropy_coeff": values["ent_coef"],
    }
    if fast:
        training.update(
            train_batch_size_per_learner=values["n_steps"],
            minibatch_size=values["batch_size"],
            num_epochs=values["n_epochs"],
        )
        config = config.env_runners(
            num_env_runners=num_env_runners,
            num_envs_per_env_runner=envs_per_env_runner,
            episodes_to_numpy=False,
            sample_timeout_s=sample_timeout_s,
        ).callbacks(on_environment_created=one_torch_thread)
    else:
        config = config.env_runners(num_env_runners=num_env_runners)
    return (
        config.training(**training)
        .learners(num_learners=0)
        .callbacks(on_train_result=_Report(single_agent, config.sample_timeout_s))
        .debugging(seed=seed)
        .reporting(metrics_num_episodes_for_smoothing=100)
    )


def _same_id(agent_id: str, episode: Any = None, **kwargs: Any) -> str:
    """Policy mapping: each player learns its own RL module, named after it."""
    return agent_id
