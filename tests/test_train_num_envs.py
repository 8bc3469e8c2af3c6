"""``train.py --num-envs N`` with MaskablePPO: training on the env's native vector env."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py lives at the root

import train
from agents.config import Hyperparameters
from agents.training import NormalizedVecReward, native_vec_env, run_setup
from baselines.sparse import exhaustive
from fdia_env.envs.sequential import PlanOrderPolicy
from fdia_env.vector.sb3 import SB3VecEnv
from fdia_env.vector.sequential import SequentialVectorEnv

pytest.importorskip("pandapower")

TINY = ["--no-progress-bar", "--final-eval-episodes", "2", "--eval-freq", "0"]
TINY_PPO = ["--n-steps", "16", "--batch-size", "16", "--n-epochs", "1"]


def test_maskable_ppo_trains_on_the_native_vector_env_of_num_envs_members(tmp_path):
    result = train.main(
        [
            "attacker", "--scenario", "grid-ieee14", "--env-kwargs", "budget", "2", "horizon",
            "1", "--num-envs", "4", "--total-timesteps", "128", *TINY, *TINY_PPO,
            "--runs-root", str(tmp_path / "runs"),
        ]
    )  # fmt: skip
    model = result.model
    assert model.n_envs == 4 and model.num_timesteps == 128  # 2 rollouts of 4 x 16 decisions
    venv = model.get_env()
    assert isinstance(venv, NormalizedVecReward)  # rewards rescaled as with one env
    native = venv.venv.venv  # inside the VecMonitor
    assert isinstance(native, SB3VecEnv) and isinstance(native.venv, SequentialVectorEnv)
    assert native.venv.increasing and native.venv.num_envs == 4  # the presets' order
    config = json.loads((result.run_dir / "config.json").read_text())
    assert config["resolved"]["algo"] == "MaskablePPO"
    assert config["config"]["num_envs"] == 4
    rows = result.evaluations
    assert rows["EXS"].score == pytest.approx(1.0, rel=1e-12)
    assert 0.0 <= rows["learned (MaskablePPO)"].score <= 1.0 + 1e-12


def test_the_vector_rewards_map_nothing_to_0_and_the_optimum_to_1():
    kwargs = {"scenario": "ch4-position", "budget": 2, "horizon": 3, "action": "sequential"}
    best = exhaustive("ch4-position", budget=2, horizon=3)
    nothing = -34.5  # any shift and scale: the map is checked against the raw returns
    venv = native_vec_env(
        "fdia_env/SparseAttack-v2", {**kwargs, "order": "increasing"}, 3, (nothing, 2.0)
    )
    raw = native_vec_env("fdia_env/SparseAttack-v2", {**kwargs, "order": "increasing"}, 3)
    policy = PlanOrderPolicy.from_result(best)
    for env in (venv, raw):
        env.seed(0)
    obs = venv.reset()
    raw.reset()
    totals, totals_raw = np.zeros(3), np.zeros(3)
    done = np.zeros(3, dtype=bool)
    while not done.all():
        actions = np.where([0, 1, 1], policy.predict(obs)[0], 0)  # member 0 attacks nothing
        obs, r, d, _ = venv.step(actions)
        _, r_raw, _, _ = raw.step(actions)
        totals += np.where(done, 0.0, r)
        totals_raw += np.where(done, 0.0, r_raw)
        done |= d
    np.testing.assert_allclose(totals, (totals_raw - nothing) / 2.0, rtol=1e-5)
    assert totals_raw[1] == pytest.approx(best.value, rel=1e-5)  # float32 rewards of SB3
    with pytest.raises(ValueError, match="scale > 0"):
        NormalizedVecReward(raw, 0.0, 0.0)


def test_num_envs_names_what_it_applies_to(tmp_path):
    runs = ["--runs-root", str(tmp_path / "runs")]
    with pytest.raises(ValueError, match="--num-envs applies to --algo torch-ppo and MaskablePPO"):
        train.main(
            ["attacker", "--scenario", "grid-ieee14", "--algo", "PPO", "--num-envs", "4", *runs]
        )
    with pytest.raises(ValueError, match=r"num_envs \(--num-envs\) trains on the env's native"):
        native_vec_env("fdia_env/StealthDefender-v0", {}, 2)  # one without a native vector env
    assert not (tmp_path / "runs").exists()


def test_a_game_view_trains_against_its_fixed_opponent_on_the_native_vector_env(tmp_path):
    from fdia_env.vector.sequential_game import SequentialGameVectorEnv

    result = train.main(
        [
            "attacker", "--env", "sensor_game_v0", "--scenario", "grid-ieee14", "--opponent",
            "equilibrium", "--num-envs", "2", "--total-timesteps", "32", *TINY, *TINY_PPO,
            "--runs-root", str(tmp_path / "runs"),
        ]
    )  # fmt: skip
    native = result.model.get_env().venv.venv
    assert isinstance(native, SB3VecEnv) and isinstance(native.venv, SequentialGameVectorEnv)
    probs = native.venv.opponent.probs  # the LP equilibrium's mix, not the uniform one
    assert probs.shape == (596,) and probs.max() > 10 / 596


def test_grid_presets_train_on_8_native_members_unless_num_envs_or_n_steps_is_given():
    hp = Hyperparameters()
    grid = ("sparse_attack_v2", "attacker", "grid-ieee14", {})
    table = run_setup(*grid, None, hp)
    assert (table.algo, table.num_envs) == ("MaskablePPO", 8)
    assert (table.hp.n_steps, table.hp.batch_size) == (128, 256)  # 1,024 decisions per update
    for env in ("sparse_attack_v0", "sparse_attack_v1"):  # every version, every grid preset
        for scenario in ("grid-ieee14-rtu", "grid-ieee118"):
            assert run_setup(env, "attacker", scenario, {}, None, hp).num_envs == 8
    # --num-envs or --n-steps replaces the vector setting: the algorithm's defaults otherwise
    given = run_setup(*grid, None, hp, num_envs=4)
    assert (given.num_envs, given.hp.n_steps, given.hp.batch_size) == (4, None, None)
    one = run_setup(*grid, None, Hyperparameters(n_steps=256))
    assert (one.num_envs, one.hp.n_steps, one.hp.batch_size) == (None, 256, None)
    batch = run_setup(*grid, None, Hyperparameters(batch_size=64))  # the command line wins
    assert (batch.num_envs, batch.hp.n_steps, batch.hp.batch_size) == (8, 128, 64)
    # only MaskablePPO, only the table's format, only the grid presets
    assert run_setup(*grid, "PPO", hp).num_envs is None
    torch = run_setup(*grid, "torch-ppo", hp)
    assert torch.num_envs is None and torch.hp.n_steps is None  # torch-ppo's own members
    multibinary = run_setup(*grid[:3], {"action": '"multibinary"'}, None, hp)
    assert multibinary.num_envs is None and multibinary.hp == hp
    dc = run_setup("sparse_attack_v2", "attacker", "dc-ieee14-50", {}, None, hp)
    assert (dc.num_envs, dc.hp.n_steps, dc.hp.ent_coef) == (8, 128, 0.05)  # its own entropy
    assert run_setup("sensor_game_v0", "attacker", "grid-ieee14", {}, None, hp).num_envs is None
    assert run_setup("sparse_attack_v2", "attacker", None, {}, None, hp).num_envs is None


def test_train_py_trains_a_grid_preset_on_8_native_members_by_default(tmp_path, capsys):
    result = train.main(
        [
            "attacker", "--scenario", "grid-ieee14", "--env-kwargs", "budget", "2", "horizon",
            "1", "--total-timesteps", "1024", "--n-epochs", "1", *TINY,
            "--runs-root", str(tmp_path / "runs"),
        ]
    )  # fmt: skip
    model = result.model
    assert (model.n_envs, model.n_steps, model.batch_size) == (8, 128, 256)
    assert model.num_timesteps == 1024  # one rollout of 8 x 128 decisions
    native = model.get_env().venv.venv
    assert isinstance(native, SB3VecEnv) and native.venv.increasing
    config = json.loads((result.run_dir / "config.json").read_text())
    assert config["config"]["num_envs"] is None  # not given: the scenario's
    assert config["resolved"]["num_envs"] == 8
    assert config["resolved"]["hyperparameters"]["n_steps"] == 128
    assert "(seed 0, 8 envs)" in capsys.readouterr().out
