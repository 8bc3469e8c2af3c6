"""The ecosystem's real clients on every env: TorchRL, Tianshou, SuperSuit + SB3, PettingZoo."""

import contextlib
import io
import logging
import re
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from pettingzoo.test import max_cycles_test, performance_benchmark, render_test

import fdia_env
from fdia_env import (
    detection_game_v0,
    sensor_game_v0,
    sparse_attack_v0,
)
from fdia_env.registration import (
    ENV_NAMES,
    GYM_IDS,
    kalman_env_names,
    kalman_gym_ids,
    load,
    vector_ids,
)
from fdia_env.wrappers import flatten_observation_v0, shared_policy_v0

CLIENTS_PAGE = Path(__file__).resolve().parent.parent / "docs" / "guide" / "clients.md"
MODULES = [load(name) for name in ENV_NAMES]  # every entry of the table of environments
pytestmark = pytest.mark.filterwarnings("ignore")


# --- the clients page: every snippet prints the output shown under it -------------------------
def page_snippets() -> list[tuple[str, str]]:
    """(code, shown output) of each snippet of docs/guide/clients.md, in page order."""
    text = CLIENTS_PAGE.read_text(encoding="utf-8")
    fence = r"```(?:python|\{code-block\} python)\n(.*?)```\n\n```(?:text)?\n(.*?)```"
    return re.findall(fence, text, flags=re.S)


def run_snippet(code: str, name: str) -> str:
    """What ``code`` prints (TorchRL's INFO log lines, timestamped, are not shown on the page)."""
    import torchrl  # noqa: F401  (its import sets the level of its logger)

    out = io.StringIO()
    log = logging.getLogger("torchrl")
    level = log.level
    log.setLevel(logging.WARNING)
    try:
        with contextlib.redirect_stdout(out), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            exec(compile(code, name, "exec"), {"__name__": "__main__"})
    finally:
        log.setLevel(level)
    return out.getvalue()


def test_the_clients_page_opens_with_the_spawned_worker_id_form():
    snippets = page_snippets()
    assert len(snippets) == 6
    text = CLIENTS_PAGE.read_text(encoding="utf-8")
    first_section = text.split("\n## ", 2)[1]
    assert first_section.startswith("Workers in other processes")
    assert 'GymEnv("fdia_env:fdia_env/' in snippets[0][0]
    # every family is in a TorchRL, a Tianshou and an SB3 snippet
    families = ("sparse", "covariance", "sensor", "detection")
    for code in (snippets[1][0], snippets[2][0] + snippets[3][0], snippets[4][0]):
        assert all(family in code.lower() for family in families)  # TorchRL, Tianshou, SB3


@pytest.mark.parametrize("index", range(len(page_snippets())), ids=lambda i: f"snippet{i + 1}")
def test_clients_page_snippet_prints_what_the_page_shows(index):
    code, shown = page_snippets()[index]
    assert run_snippet(code, f"docs/guide/clients.md, snippet {index + 1}") == shown


# --- PettingZoo's own test set (the API and seed tests are in test_envs_api.py) ------------
@pytest.mark.parametrize("module", [load(n) for n in kalman_env_names()], ids=lambda m: m.NAME)
def test_pettingzoo_render_max_cycles_and_performance_tests(module):
    with contextlib.redirect_stdout(io.StringIO()) as out:
        render_test(module.env)  # human, ansi and rgb_array
        max_cycles_test(module)
        performance_benchmark(module.env())
    assert "Φ(trace)" in out.getvalue()  # "human" printed the ansi line


# --- TorchRL -------------------------------------------------------------------------------
@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.NAME)
@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_torchrl_pettingzoo_wrapper_rollout_and_specs(module, dynamics):
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs

    env = PettingZooWrapper(module.parallel_env(dynamics=dynamics), use_mask=True)
    check_env_specs(env)
    rollout = env.rollout(20, break_when_any_done=False)
    assert rollout.batch_size[0] == 20
    group = next(iter(env.group_map))
    reward = rollout["next", group, "reward"]
    assert torch_finite(reward)


def torch_finite(t):
    import torch

    return bool(torch.isfinite(t).all())


@pytest.mark.parametrize("env_id", sorted(GYM_IDS))
def test_torchrl_gym_env_with_four_async_envs(env_id):
    from torchrl.envs.libs.gym import GymEnv

    # the workers are spawned fresh processes: Gymnasium's "module:id" form imports fdia_env
    # there first (Gymnasium 1.x has no plugin discovery that would do it)
    env = GymEnv(f"fdia_env:{env_id}", num_envs=4)
    try:
        rollout = env.rollout(8, break_when_any_done=False)
    finally:
        env.close()
    assert tuple(rollout.batch_size) == (4, 8)
    assert torch_finite(rollout["next", "reward"])


@pytest.mark.parametrize("env_id", sorted(kalman_gym_ids()))  # the engine's vector env
def test_torchrl_gym_wrapper_on_the_native_vector_env(env_id):
    from torchrl.envs.libs.gym import GymWrapper
    from torchrl.envs.utils import check_env_specs

    venv = gym.make_vec(
        env_id,
        num_envs=4,
        vectorization_mode="vector_entry_point",
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,  # what TorchRL asks for
    )
    env = GymWrapper(venv)
    check_env_specs(env)
    rollout = env.rollout(10, break_when_any_done=False)
    assert tuple(rollout.batch_size) == (4, 10)
    assert "phi" in rollout.keys()  # the stable infos become specs


# --- TorchRL's native face of the native vector env (fdia_env.torchrl) -------------------------
TORCHRL_CASES = [  # the engine's vector env (FdiaTorchRLEnv wraps it) on each of its backends
    (env_id, b)
    for b in ("torch", "numpy")
    for env_id in sorted(vector_ids(b))
    if env_id in kalman_gym_ids()
]


@pytest.mark.parametrize(("env_id", "backend"), TORCHRL_CASES)
def test_fdia_torchrl_env_passes_check_env_specs_on_every_id_and_backend(env_id, backend):
    import torch
    from torchrl.envs.utils import check_env_specs

    from fdia_env.torchrl import FdiaTorchRLEnv

    # no autoreset_mode to pass: the face builds the native vector env with SAME_STEP itself
    env = FdiaTorchRLEnv(env_id, num_envs=3, backend=backend)
    assert env.batch_size == torch.Size([3]) and env.batch_locked
    check_env_specs(env, seed=0)
    rollout = env.rollout(8, break_when_any_done=False)
    assert tuple(rollout.batch_size) == (3, 8)
    assert rollout["next", "reward"].dtype == torch.float32
    assert rollout["observation"].dtype == torch.float32
    assert torch_finite(rollout["next", "phi"])
    horizon = env.venv.spec_episode.horizon
    assert int(rollout["next", "done"].sum()) == 3 * (8 // horizon)  # every member, every end


def test_fdia_torchrl_env_replays_gymwrapper_on_the_same_step_numpy_env():
    """The face's last observation of an episode and its restart match TorchRL's GymWrapper."""
    import torch
    from torchrl.envs.libs.gym import GymWrapper

    from fdia_env.torchrl import FdiaTorchRLEnv

    env_id, kwargs = "fdia_env/SparseAttack-v0", {"dynamics": "expected"}  # seed-free draws

    def policy(td):
        td["action"] = (td["observation"][..., 1] > 0).long() * 5 + 1  # legal, state-dependent
        return td

    ours = FdiaTorchRLEnv(env_id, num_envs=2, backend="numpy", **kwargs)
    venv = gym.make_vec(
        env_id,
        num_envs=2,
        vectorization_mode="vector_entry_point",
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
        **kwargs,
    )
    theirs = GymWrapper(venv, categorical_action_encoding=True)
    a = ours.rollout(14, policy, break_when_any_done=False)
    b = theirs.rollout(14, policy, break_when_any_done=False)
    assert int(a["next", "done"].sum()) == 4  # two episodes of 6 steps end in each member
    for key in ["observation", ("next", "observation"), ("next", "done")]:
        assert torch.equal(a[key], b[key]), key
    assert torch.allclose(a["next", "reward"], b["next", "reward"].float())
    # the step that ends an episode returns its last observation, not the restarted one
    end = a["next", "done"].squeeze(-1)
    assert not torch.equal(a["next", "observation"][end], a["observation"][:, 1:][end[:, :-1]])


def test_fdia_torchrl_env_refuses_bad_input_by_name():
    from fdia_env.torchrl import FdiaTorchRLEnv

    with pytest.raises(ValueError, match="env must be one of"):
        FdiaTorchRLEnv("CartPole-v1")
    with pytest.raises(ValueError, match="autoreset_mode"):
        FdiaTorchRLEnv("fdia_env/SparseAttack-v0", autoreset_mode="NextStep")
    venv = gym.make_vec("fdia_env/SparseAttack-v0", num_envs=2)
    with pytest.raises(ValueError, match="SAME_STEP"):
        FdiaTorchRLEnv(venv)
    env = FdiaTorchRLEnv("fdia_env:fdia_env/SparseAttack-v0", num_envs=2)
    td = env.reset()
    td["_reset"] = td["done"].clone().fill_(False)
    td["_reset"][1] = True
    with pytest.raises(ValueError, match=r"members \[1\] whose episode is still running"):
        env.reset(td)


def test_torchrl_collector_and_clip_ppo_loss_on_the_torch_backend():
    """TorchRL's own training pieces on the torch backend: masked policy, GAE, PPO steps."""
    import torch
    from tensordict.nn import TensorDictModule
    from torch import nn
    from torchrl.collectors import Collector
    from torchrl.modules import MaskedCategorical, ProbabilisticActor, ValueOperator
    from torchrl.objectives import ClipPPOLoss

    from fdia_env.torchrl import FdiaTorchRLEnv

    torch.manual_seed(0)
    # an illegal action would raise in the env: the mask reaches the policy's distribution
    env = FdiaTorchRLEnv(
        "fdia_env/SparseAttack-v0", num_envs=8, backend="torch", illegal_action="error"
    )
    env.set_seed(0)
    d, n = env.observation_spec["observation"].shape[-1], env.action_spec.n
    net = nn.Sequential(nn.Linear(d, 32), nn.Tanh(), nn.Linear(32, n))
    actor = ProbabilisticActor(
        TensorDictModule(net, in_keys=["observation"], out_keys=["logits"]),
        in_keys={"logits": "logits", "mask": "action_mask"},
        out_keys=["action"],
        distribution_class=MaskedCategorical,
        return_log_prob=True,
        spec=env.action_spec,
    )
    critic = ValueOperator(
        nn.Sequential(nn.Linear(d, 32), nn.Tanh(), nn.Linear(32, 1)), in_keys=["observation"]
    )
    loss = ClipPPOLoss(actor, critic, entropy_coeff=0.01)
    loss.make_value_estimator(gamma=1.0, lmbda=0.95)
    optim = torch.optim.Adam(loss.parameters(), lr=1e-2)
    collector = Collector(env, actor, frames_per_batch=96, total_frames=288)
    batches = 0
    for batch in collector:
        assert tuple(batch.batch_size) == (8, 12)
        legal = batch["action_mask"].gather(-1, batch["action"].unsqueeze(-1))
        assert bool(legal.all())
        with torch.no_grad():
            loss.value_estimator(batch, params=loss.critic_network_params, target_params=None)
        losses = loss(batch.reshape(-1))
        total = losses["loss_objective"] + losses["loss_critic"] + losses["loss_entropy"]
        assert torch_finite(total)
        optim.zero_grad()
        total.backward()
        optim.step()
        collector.update_policy_weights_()
        batches += 1
    collector.shutdown()
    assert batches == 3
    assert int(batch["next", "done"].sum()) == 16  # 12 steps: two 6-step episodes per member


# --- Tianshou ------------------------------------------------------------------------------
@pytest.mark.parametrize("module", [sensor_game_v0, sparse_attack_v0], ids=lambda m: m.NAME)
def test_tianshou_pettingzoo_env_and_collector(module):
    from tianshou.algorithm.multiagent.marl import MultiAgentPolicy
    from tianshou.algorithm.random import MARLRandomDiscreteMaskedOffPolicyAlgorithm
    from tianshou.data import Collector, VectorReplayBuffer
    from tianshou.env import DummyVectorEnv, PettingZooEnv

    def make():
        return PettingZooEnv(module.env())

    env = make()
    policies = {
        agent: MARLRandomDiscreteMaskedOffPolicyAlgorithm(env.action_space).policy
        for agent in env.agents
    }
    venv = DummyVectorEnv([make, make])
    collector = Collector(MultiAgentPolicy(policies), venv, VectorReplayBuffer(400, 2))
    collector.reset()
    stats = collector.collect(n_episode=6)
    assert stats.n_collected_episodes >= 6
    assert np.all(np.isfinite(stats.returns))


# --- SuperSuit + stable-baselines3 ---------------------------------------------------------
def supersuit_ppo(parallel, policy):
    import supersuit as ss
    from stable_baselines3 import PPO

    venv = ss.pettingzoo_env_to_vec_env_v1(parallel)
    venv = ss.concat_vec_envs_v1(venv, 2, num_cpus=0, base_class="stable_baselines3")
    model = PPO(policy, venv, n_steps=64, batch_size=64, n_epochs=1, device="cpu")
    model.learn(256)
    return model


def test_supersuit_sb3_ppo_on_the_sensor_game_with_a_shared_policy():
    model = supersuit_ppo(shared_policy_v0(sensor_game_v0.parallel_env(rounds=3)), "MlpPolicy")
    assert model.num_timesteps >= 256


def test_supersuit_sb3_ppo_on_sparse_attacks_dict_and_flattened():
    assert supersuit_ppo(sparse_attack_v0.parallel_env(), "MultiInputPolicy").num_timesteps >= 256
    flat = flatten_observation_v0(sparse_attack_v0.parallel_env(illegal_action="noop"))
    assert supersuit_ppo(flat, "MlpPolicy").num_timesteps >= 256


def test_supersuit_sb3_ppo_on_the_detection_game_with_padded_actions():
    model = supersuit_ppo(shared_policy_v0(detection_game_v0.parallel_env()), "MlpPolicy")
    assert model.num_timesteps >= 256


# --- Gymnasium -----------------------------------------------------------------------------
@pytest.mark.parametrize("env_id", sorted(GYM_IDS))
def test_gymnasium_check_env_on_every_id(env_id):
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(gym.make(env_id).unwrapped, skip_render_check=False)
    assert fdia_env.__version__
