"""train.py on a grid preset (grid-ieee14) for every player, with the scenario table's defaults.

Tiny budgets: the sparse attacker on c = 2, N = 1 (EXS over 34 sensors is the reference), the
sensor game's players and the game command on the preset itself (k = 2: 596 subsets a side).
"""

import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py lives at the root

import train
from agents.config import (
    SCENARIO_DEFAULTS,
    SPARSE_ENVS,
    Hyperparameters,
    resolved_hyperparameters,
    scenario_defaults,
    with_defaults,
)
from agents.registry import get
from agents.torch_ppo import TorchPPOConfig
from agents.training import NormalizedReward, null_return, run_setup
from baselines.game import exploitability
from baselines.sparse import exhaustive

pytest.importorskip("pandapower")

TINY = ["--no-progress-bar", "--final-eval-episodes", "2", "--eval-freq", "0"]
TINY_PPO = ["--n-steps", "32", "--batch-size", "16", "--n-epochs", "1"]


def run(tmp_path, *args):
    return train.main([*args, "--runs-root", str(tmp_path / "runs")])


def test_the_table_picks_the_sequential_format_and_masked_ppo_on_grid_presets():
    setup = run_setup("sparse_attack_v0", "attacker", "grid-ieee14", {}, None, Hyperparameters())
    assert setup.algo == "MaskablePPO" and setup.normalize_reward
    assert setup.env_kwargs == {
        "scenario": "grid-ieee14", "action": "sequential", "order": "increasing"
    }  # fmt: skip
    # torch-ppo's observation normalisation is off there; nothing else leaves the defaults
    assert SCENARIO_DEFAULTS["sparse_attack_v0", "grid-ieee14"].hyperparameters == {
        "norm_obs": False
    }
    # MaskablePPO's own defaults (norm_obs is not its own) but for its vector setting: 8 native
    # members of 128 decisions per rollout, minibatches of 256
    assert setup.hp == Hyperparameters(n_steps=128, batch_size=256) and setup.num_envs == 8
    # the time-major order (the env's default) leaves the table
    timed = run_setup(
        "sparse_attack_v0", "attacker", "grid-ieee14", {"order": '"time"'}, None,
        Hyperparameters(),
    )  # fmt: skip
    assert timed.env_kwargs["order"] == "time" and not timed.normalize_reward
    # the command line wins over the table
    given = run_setup(
        "sparse_attack_v0", "attacker", "grid-ieee14", {}, "PPO", Hyperparameters(n_steps=64),
        normalize_reward=False,
    )  # fmt: skip
    assert (given.algo, given.hp.n_steps, given.normalize_reward) == ("PPO", 64, False)
    # another action format leaves the table: the algorithm's own defaults
    other = run_setup(
        "sparse_attack_v0", "attacker", "grid-ieee14", {"action": '"multibinary"'}, None,
        Hyperparameters(),
    )  # fmt: skip
    assert other.algo == "MaskablePPO" and other.hp == Hyperparameters()
    assert other.num_envs is None  # one env
    assert "order" not in other.env_kwargs  # the table's options go with its format
    assert not other.normalize_reward
    # a hyperparameter the algorithm does not take is not filled in
    defaults = scenario_defaults("sensor_game_v0", "grid-ieee14", {"action": "sequential"})
    assert defaults.hyperparameters["n_steps"] == 256
    assert with_defaults("DQN", Hyperparameters(), defaults).n_steps is None
    # scenarios outside the table are unchanged
    plain = run_setup("sparse_attack_v0", "attacker", None, {}, None, Hyperparameters())
    assert plain.hp == Hyperparameters() and not plain.normalize_reward


def test_every_sparse_version_has_the_table_and_the_same_null_return():
    setups = [
        run_setup(env, "attacker", "grid-ieee14", {}, None, Hyperparameters())
        for env in SPARSE_ENVS
    ]
    assert SPARSE_ENVS[0] == "sparse_attack_v2"  # train.py's default env
    assert all(s.env_kwargs == setups[-1].env_kwargs for s in setups)
    assert all(s.algo == "MaskablePPO" and s.normalize_reward for s in setups)
    shifts = []
    for env in SPARSE_ENVS:
        entry = get(env)
        with entry.make("grid-ieee14", budget=2, horizon=1) as view:
            shifts.append(null_return(entry, view))
    assert shifts[0] > 0  # attacking nothing leaves the steady-state trace, in every version
    assert shifts == [shifts[0]] * len(SPARSE_ENVS)


def test_normalized_reward_maps_doing_nothing_to_0_and_the_optimum_to_1():
    kwargs = {"scenario": "grid-ieee14", "action": "sequential", "budget": 2, "horizon": 1}
    entry = get("sparse_attack_v0")
    best = exhaustive("grid-ieee14", budget=2, horizon=1)
    with entry.make("grid-ieee14", budget=2, horizon=1) as env:
        shift = null_return(entry, env)
        reference = entry.reference_of(env)
    assert reference.value == pytest.approx(best.value, rel=1e-12)
    assert 0 < shift < best.value  # attacking nothing leaves the steady-state trace
    wrapped = NormalizedReward(gym.make("fdia_env/SparseAttack-v0", **kwargs), shift,
                               best.value - shift)  # fmt: skip
    policy = best.policy("sequential")
    obs, _ = wrapped.reset(seed=0)
    total, done = 0.0, False
    while not done:
        action, _ = policy.predict(obs)
        obs, reward, term, trunc, _ = wrapped.step(int(action))
        total, done = total + reward, term or trunc
    assert total == pytest.approx(1.0, abs=1e-9)
    with pytest.raises(ValueError, match="scale > 0"):
        NormalizedReward(gym.make("fdia_env/SparseAttack-v0", **kwargs), 0.0, 0.0)


@pytest.mark.filterwarnings("error::DeprecationWarning")  # the newest version: no notice
def test_attacker_command_trains_on_grid_ieee14_with_the_table_defaults(tmp_path, capsys):
    result = run(
        tmp_path, "attacker", "--scenario", "grid-ieee14", "--env-kwargs", "budget", "2",
        "horizon", "1", "--total-timesteps", "64", *TINY, *TINY_PPO,
    )  # fmt: skip
    assert result.run_dir.name.startswith("sparse_attack_v2-MaskablePPO-s0-")
    config = json.loads((result.run_dir / "config.json").read_text())["resolved"]
    assert config["env_kwargs"]["action"] == "sequential"
    assert config["env_kwargs"]["order"] == "increasing"  # a plan's pairs in increasing order
    assert config["hyperparameters"]["net_arch"] == [64, 64]
    assert result.model.get_env().envs[0].unwrapped.parallel.increasing  # the env's own order
    norm = config["reward_normalization"]
    best = exhaustive("grid-ieee14", budget=2, horizon=1).value
    assert norm["shift"] + norm["scale"] == pytest.approx(best, rel=1e-12)
    rows = result.evaluations
    assert rows["EXS"].score == pytest.approx(1.0, rel=1e-12)
    assert 0.5 < rows["learned (MaskablePPO)"].score <= 1.0 + 1e-12
    assert "reference (EXS)" in capsys.readouterr().out


@pytest.mark.parametrize("agent", ["attacker", "defender"])
def test_sensor_game_players_train_on_grid_ieee14(tmp_path, agent):
    result = run(
        tmp_path, agent, "--env", "sensor_game_v0", "--scenario", "grid-ieee14",
        "--total-timesteps", "32", *TINY, *TINY_PPO,
    )  # fmt: skip
    learned = result.evaluations["learned (MaskablePPO)"]
    assert learned.score_name == "exploitability"
    strategy = learned.strategy
    # k = 2 of 34 meters: the attacker's 34 + 561 subsets, the defender's also the empty one
    assert strategy.shape == ((595,) if agent == "attacker" else (596,))
    assert strategy.sum() == pytest.approx(1.0) and strategy.max() == 1.0  # a pure strategy
    assert result.evaluations["game value (LP)"].score == pytest.approx(0.0, abs=1e-12)


def test_game_command_runs_psro_on_grid_ieee14_in_the_sequential_format(tmp_path):
    result = run(
        tmp_path, "game", "--scenario", "grid-ieee14", "--iterations", "1",
        "--steps-per-iteration", "32", *TINY_PPO, "--no-progress-bar",
        "--final-eval-episodes", "2",
    )  # fmt: skip
    assert "-psro-MaskablePPO-" in result.run_dir.name
    (h,) = result.history
    entry = get("sensor_game_v0", "attacker")
    with entry.make(**entry.env_kwargs("grid-ieee14")) as env:
        L = entry.reference_of(env).matrix_game()
    assert len(result.x) == L.shape[0] and len(result.y) == L.shape[1]
    assert np.count_nonzero(result.x) == 1 and np.count_nonzero(result.y) == 1
    e = exploitability(L, result.x, result.y)
    assert h["nash_conv"] == pytest.approx(e.nash_conv, rel=1e-9)


def test_stop_prob_sets_the_initial_probability_of_stop():
    from sb3_contrib import MaskablePPO

    from agents.algos import build_model
    from agents.config import algo_kwargs

    env = gym.make("fdia_env/SparseAttack-v0", scenario="ch4-position", action="sequential")
    kwargs = algo_kwargs("MaskablePPO", Hyperparameters(stop_prob=0.9))
    model = build_model("MaskablePPO", env, kwargs, seed=0)
    assert isinstance(model, MaskablePPO)
    obs, _ = env.reset(seed=0)
    tensor = model.policy.obs_to_tensor(obs)[0]
    probs = model.policy.get_distribution(tensor).distribution.probs.detach().numpy()[0]
    assert probs[0] == pytest.approx(0.9, abs=0.01)  # the head's weights are tiny, not zero
    assert probs[1:] == pytest.approx(np.full(3, 0.1 / 3), abs=0.01)
    with pytest.raises(ValueError, match="stop_prob"):
        Hyperparameters(stop_prob=1.0)
    dqn = algo_kwargs("DQN", Hyperparameters())
    assert "stop_prob" not in dqn
    with pytest.raises(ValueError, match="stop_prob does not apply to DQN"):
        algo_kwargs("DQN", Hyperparameters(stop_prob=0.5))


def test_torch_ppo_takes_stop_prob_from_the_hyperparameters():
    import torch

    from agents.config import ALGO_DEFAULTS, TORCH_PPO
    from agents.torch_ppo import TorchPPOConfig, make_torch_env, train_torch_ppo

    hp = {**ALGO_DEFAULTS[TORCH_PPO], "stop_prob": 0.9, "learning_rate": 1e-12}
    config = TorchPPOConfig.from_hyperparameters(hp, 8, 4)
    assert config.stop_prob == 0.9
    with pytest.raises(ValueError, match="stop_prob"):
        TorchPPOConfig(stop_prob=0.0)
    venv = make_torch_env(
        "fdia_env/SparseAttack-v0", 4, "cpu", scenario="ch4-position", action="sequential"
    )
    result = train_torch_ppo(venv, config, seed=0)  # one iteration at a step size of 1e-12
    venv.close()
    logits = result.policy.model.actor[-1].bias.detach()
    probs = torch.softmax(logits, 0)
    assert float(probs[0]) == pytest.approx(0.9, abs=1e-6)  # the bias: 0.9 to stop


def test_torch_ppo_on_a_grid_preset_trains_without_observation_normalisation():
    hp = Hyperparameters()
    setup = run_setup("sparse_attack_v0", "attacker", "grid-ieee14", {}, "torch-ppo", hp)
    assert setup.hp.norm_obs is False
    resolved = resolved_hyperparameters("torch-ppo", setup.hp)
    assert TorchPPOConfig.from_hyperparameters(resolved, 1024, 8).norm_obs is False
    # the algorithm's default elsewhere, and the command line wins over the table
    assert resolved_hyperparameters("torch-ppo", hp)["norm_obs"] is True
    given = Hyperparameters(norm_obs=True)
    kept = run_setup("sparse_attack_v0", "attacker", "grid-ieee14", {}, "torch-ppo", given)
    assert kept.hp.norm_obs is True
    with pytest.raises(ValueError, match="norm_obs does not apply to MaskablePPO"):
        resolved_hyperparameters("MaskablePPO", given)
    with pytest.raises(TypeError, match="norm_obs"):
        Hyperparameters(norm_obs="yes")
