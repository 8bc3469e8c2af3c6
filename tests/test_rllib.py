"""RLlib backend (agents.rllib): env forms, config, one iteration of each kind, a Tune sweep.

Needs the fdia-env[rllib] extra (skipped without it; tests/test_rllib_cli.py runs without).
One local Ray with 2 CPUs serves the module; each test trains one PPO iteration of 500-1,000
steps.
"""

from __future__ import annotations

import json
import math
import pickle

import numpy as np
import pytest

from agents.config import Hyperparameters, SweepConfig

rllib = pytest.importorskip("ray.rllib", reason="needs the fdia-env[rllib] extra")

EXS = 0.0327856  # ch4-position, budget 5, horizon 6 (README, agents.registry doctest)


@pytest.fixture(scope="module")
def local_ray():
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def test_multi_agent_env_gives_masked_players_rllibs_observation_form():
    from agents.rllib.envs import make_multi_agent

    env = make_multi_agent("sparse_attack_v0", {"scenario": "ch4-position"})
    space = env.observation_spaces["attacker"]
    assert sorted(space.spaces) == ["action_mask", "observations"]
    assert space["action_mask"].dtype == np.float32
    obs, _ = env.reset(seed=0)
    assert space.contains(obs["attacker"])
    np.testing.assert_array_equal(obs["attacker"]["action_mask"], np.ones(8))  # budget 5 ≥ 3
    env.step({"attacker": 0b111})  # 3 + 2 sensors: the budget is spent, only "nothing" is legal
    obs, _, terms, truncs, _ = env.step({"attacker": 0b011})
    np.testing.assert_array_equal(obs["attacker"]["action_mask"], np.eye(8)[0])
    assert terms["__all__"] is False and truncs["__all__"] is False


def test_sensor_game_multi_agent_env_is_zero_sum_and_ends_for_all():
    from agents.rllib.envs import make_multi_agent
    from baselines.game import payoff_matrix

    env = make_multi_agent("sensor_game_v0", {"scenario": "ch5-game"})
    env.reset(seed=0)
    _, rewards, terms, truncs, _ = env.step({"attacker": 0, "defender": 6})
    p = env.parallel
    L = payoff_matrix(p.scenario, p.attack.power, p.attack.allocation)
    assert rewards["attacker"] == pytest.approx(L[6, 0], rel=1e-12)
    assert rewards["defender"] == -rewards["attacker"]
    assert terms == {"attacker": True, "defender": True, "__all__": True}
    assert truncs["__all__"] is False
    assert env.agents == ["attacker", "defender"]  # RLlib checks the last step against it


def test_rllib_hyperparameters_reject_other_algorithms_options():
    from agents.rllib.config import RLLIB_DEFAULTS, rllib_hyperparameters

    assert rllib_hyperparameters()["n_steps"] == RLLIB_DEFAULTS["n_steps"]
    with pytest.raises(ValueError, match=r"buffer_size \(--buffer-size\) does not apply"):
        rllib_hyperparameters(Hyperparameters(buffer_size=10))
    with pytest.raises(ValueError, match=r"batch_size \(--batch-size\) \(256\) must be <="):
        rllib_hyperparameters(Hyperparameters(n_steps=128, batch_size=256))


def test_sparse_env_with_error_mode_raises_on_an_illegal_action():
    # the premise of the masked test below: an illegal sample would fail the iteration
    from fdia_env import sparse_attack_v0

    env = sparse_attack_v0.parallel_env(illegal_action="error")
    env.reset(seed=0)
    env.step({"attacker": 0b111})
    with pytest.raises(ValueError):
        env.step({"attacker": 0b111})  # 3 sensors, 2 left


def test_masked_ppo_iteration_with_remote_env_runner_samples_only_legal_actions(local_ray):
    from agents.rllib.config import agent_returns, ppo_config, steps_sampled
    from agents.rllib.policy import policy_of

    config = ppo_config(
        "fdia_env/SparseAttack-v0",
        {"scenario": "ch4-position", "illegal_action": "error"},
        hp=Hyperparameters(n_steps=600, batch_size=100, n_epochs=2),
        num_env_runners=1,
        envs_per_env_runner=4,
    )
    algo = config.build_algo()
    try:
        result = algo.train()  # an illegal action raises in the env runner, failing this
        assert steps_sampled(result) >= 600
        returns = agent_returns(result)
        assert set(returns) == {"attacker"}
        # a return of the sparse attack is Φ at the window end: above the clean steady state's
        # (attacks only raise it) and at most EXS, the optimum over every legal plan
        assert 0.0 < returns["attacker"] <= EXS * (1 + 1e-6)
        import gymnasium as gym

        policy = policy_of(algo, None, gym.spaces.Discrete(8), masked=True)
        obs = np.zeros((2, 5), np.float32)
        masks = np.array([np.eye(8)[0], np.ones(8)])
        p = policy.action_probs(obs, masks)
        assert p[0, 0] == 1.0 and np.all(p[0, 1:] == 0.0)  # masked logits: exp(-3.4e38) = 0
        np.testing.assert_allclose(p.sum(axis=1), 1.0, rtol=1e-12)
        assert policy.predict(obs[0], deterministic=True, action_masks=masks[0])[0] == 0
    finally:
        algo.stop()


# --- plain RLlib: PPOConfig().environment(name), no rl_module, on every env ------------------
def test_rllibs_own_default_module_refuses_the_masked_observation_the_default_now_reads():
    import gymnasium as gym
    import torch
    from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import (
        DefaultPPOTorchRLModule,
    )
    from ray.rllib.core.columns import Columns

    from agents.rllib.envs import make_multi_agent
    from agents.rllib.module import MaskedPPOTorchRLModule

    space = make_multi_agent("sparse_attack_v0").observation_spaces["attacker"]
    action = gym.spaces.Discrete(8)
    with pytest.raises(ValueError, match="No default encoder config for obs space=Dict"):
        DefaultPPOTorchRLModule(observation_space=space, action_space=action, model_config={})
    torch.manual_seed(0)
    module = MaskedPPOTorchRLModule(observation_space=space, action_space=action, model_config={})
    assert module.observation_space == space
    obs = {
        "observations": torch.zeros(2, 5),
        "action_mask": torch.tensor([[1.0, 0, 0, 1, 0, 0, 0, 0], [1.0] * 8]),
    }
    logits = module.forward_inference({Columns.OBS: obs})[Columns.ACTION_DIST_INPUTS]
    p = torch.softmax(logits.double(), dim=-1)
    assert torch.all(p[0, [1, 2, 4, 5, 6, 7]] == 0.0) and float(p[0, [0, 3]].sum()) == 1.0
    assert torch.all(p[1] > 0.0)
    values = module.compute_values({Columns.OBS: obs})
    assert tuple(values.shape) == (2,)
    # on a Box it is RLlib's default module: the same networks, parameter for parameter
    box = space["observations"]
    ours = MaskedPPOTorchRLModule(observation_space=box, action_space=action, model_config={})
    theirs = DefaultPPOTorchRLModule(observation_space=box, action_space=action, model_config={})
    shapes = {k: tuple(v.shape) for k, v in theirs.state_dict().items()}
    assert {k: tuple(v.shape) for k, v in ours.state_dict().items()} == shapes


def plain_names():
    from fdia_env.registration import kalman_env_names, kalman_gym_ids

    # the Kalman-filter envs: the stealthy attacker's MultiBinary action has no RLlib
    # action distribution (its catalog raises "Unsupported action space")
    return [*kalman_env_names(), *sorted(kalman_gym_ids())]


@pytest.mark.parametrize("name", plain_names())
def test_plain_ppo_config_trains_one_iteration_on_every_env(local_ray, name):
    from ray.rllib.algorithms.ppo import PPOConfig

    from agents.rllib.envs import MODULES, make_multi_agent, register_envs

    register_envs()  # the env names, and the masked default module
    # an illegal action raises in the env: the masked players' logits must be masked
    env_config = {"illegal_action": "error"} if "parse" in name else {}
    config = (
        PPOConfig()
        .environment(name, env_config=env_config)
        .env_runners(num_env_runners=0)
        .training(train_batch_size_per_learner=48, minibatch_size=48, num_epochs=1)
    )
    if name in MODULES:  # RLlib's multi-agent idiom: one module per player
        players = make_multi_agent(name).possible_agents
        config = config.multi_agent(
            policies=set(players), policy_mapping_fn=lambda agent_id, *args, **kwargs: agent_id
        )
    algo = config.build_algo()
    try:
        result = algo.train()
        assert result["env_runners"]["num_env_steps_sampled"] >= 48
        assert math.isfinite(result["learners"]["__all_modules__"]["num_env_steps_trained"])
    finally:
        algo.stop()


def test_plain_ppo_config_on_rllibs_own_pettingzoo_wrapper_masks_the_int8_mask(local_ray):
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
    from ray.tune.registry import register_env

    from agents.rllib.module import MaskedPPOTorchRLModule, register_default_module
    from fdia_env import sparse_attack_v0

    register_default_module()

    def creator(env_config):
        return ParallelPettingZooEnv(sparse_attack_v0.parallel_env(illegal_action="error"))

    register_env("pettingzoo_sparse_attack", creator)
    config = (
        PPOConfig()
        .environment("pettingzoo_sparse_attack")
        .env_runners(num_env_runners=0)
        .multi_agent(policies={"attacker"}, policy_mapping_fn=lambda agent_id, *a, **k: agent_id)
        .training(train_batch_size_per_learner=48, minibatch_size=48, num_epochs=1)
    )
    algo = config.build_algo()
    try:  # PettingZoo's {"observation", "action_mask" (int8)}: an illegal action would raise
        result = algo.train()
        assert result["env_runners"]["num_env_steps_sampled"] >= 48
        assert isinstance(algo.get_module("attacker"), MaskedPPOTorchRLModule)
    finally:
        algo.stop()


def test_plain_ppo_config_with_a_remote_env_runner_masks_there_too(local_ray):
    from ray.rllib.algorithms.ppo import PPOConfig

    from agents.rllib.envs import register_envs

    register_envs()
    config = (
        PPOConfig()
        .environment("fdia_env/SparseAttack-v0", env_config={"illegal_action": "error"})
        .env_runners(num_env_runners=1)
        .training(train_batch_size_per_learner=96, minibatch_size=96, num_epochs=1)
    )
    algo = config.build_algo()
    try:  # the env runner builds the module in its own process: an illegal action would raise
        result = algo.train()
        assert result["env_runners"]["num_env_steps_sampled"] >= 96
    finally:
        algo.stop()


def test_the_rllib_page_leads_with_ppo_config_and_prints_what_it_shows(local_ray):
    import contextlib
    import io
    import re
    from pathlib import Path

    page = (Path(__file__).resolve().parent.parent / "docs/guide/rllib.md").read_text("utf-8")
    first = re.search(r"```\{code-block\} python\n(.*?)```\n\n```text\n(.*?)```", page, re.S)
    assert page.index("ppo_config") < page.index("```bash")  # the page opens with it
    code, shown = first.group(1), first.group(2)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "docs/guide/rllib.md", "exec"), {})
    assert out.getvalue() == shown


def test_selfplay_iteration_reports_both_players_and_exact_exploitability(local_ray, tmp_path):
    import train
    from baselines.game import exploitability, payoff_matrix, solve_zero_sum
    from fdia_env import sensor_game_v0

    game = train.main(
        ["game", "--backend", "rllib", "--method", "selfplay", "--iterations", "1",
         "--steps-per-iteration", "1000", "--final-eval-episodes", "50", "--no-progress-bar",
         "--runs-root", str(tmp_path)]
    )  # fmt: skip
    rec = game.history[-1]
    returns = rec["agent_returns"]
    p = sensor_game_v0.parallel_env(scenario="ch5-game")
    L = payoff_matrix(p.scenario, p.attack.power, p.attack.allocation)
    # zero-sum: the players' returns cancel (episode_return_mean, their sum, is 0); each is a
    # mean of payoff entries
    assert returns["attacker"] == pytest.approx(-returns["defender"], abs=1e-9)
    assert L.min() < returns["attacker"] < L.max()
    assert rec["timesteps"] >= 1000
    value = solve_zero_sum(L)[2]
    e = exploitability(L, np.array(rec["x"]), np.array(rec["y"]), value)
    assert rec["nash_conv"] == pytest.approx(e.nash_conv, rel=1e-12)
    assert rec["relative_nash_conv"] == pytest.approx(e.nash_conv / value, rel=1e-12)
    assert game.value == pytest.approx(8.106030777100386, rel=1e-9)
    scores = json.loads((game.run_dir / "scores.json").read_text())
    assert scores["backend"] == "rllib" and (game.run_dir / "checkpoint").is_dir()


def test_train_attacker_rllib_is_scored_against_exs(local_ray, tmp_path):
    import train

    result = train.main(
        ["attacker", "--backend", "rllib", "--total-timesteps", "500", "--n-steps", "500",
         "--batch-size", "100", "--n-epochs", "2", "--final-eval-episodes", "3",
         "--no-progress-bar", "--runs-root", str(tmp_path)]
    )  # fmt: skip
    learned = result.evaluations["learned (RLlib PPO)"]
    assert learned.reference == pytest.approx(EXS, rel=1e-5)
    assert learned.score == pytest.approx(learned.mean / learned.reference, rel=1e-12)
    assert result.evaluations["EXS"].score == pytest.approx(1.0, abs=1e-9)
    assert result.timesteps >= 500 and result.history[-1]["agent_returns"]["attacker"] > 0


def test_tune_sweep_of_two_seeds_writes_one_results_table(local_ray, tmp_path):
    from agents.rllib.sweep import run_sweep

    cfg = SweepConfig(
        env="sparse_attack_v0",
        seeds=(0, 1),
        total_timesteps=500,
        final_eval_episodes=3,
        hp=Hyperparameters(n_steps=500, batch_size=100, n_epochs=2),
    )
    cfg.run.runs_root = tmp_path
    out = run_sweep(cfg, report=None)
    rows = out["rows"]
    assert [r["seed"] for r in rows] == [0, 1]
    for r in rows:
        assert r["error"] is None
        assert r["timesteps"] >= 500 and r["return_attacker"] > 0
        assert r["reference"] == pytest.approx(EXS, rel=1e-5)
        assert r["score"] == pytest.approx(r["eval_mean"] / r["reference"], rel=1e-12)
        assert 0 < r["score"] <= 1 + 1e-9
    table = (out["run_dir"] / "results.csv").read_text().splitlines()
    assert len(table) == 3 and "return_attacker" in table[0] and "score" in table[0]
    assert not any(math.isnan(r["score"]) for r in rows)


def test_selfplay_on_detection_game_learns_both_and_scores_the_defender(local_ray, tmp_path):
    import train

    game = train.main(
        ["game", "--backend", "rllib", "--method", "selfplay", "--env", "detection_game_v0",
         "--iterations", "1", "--steps-per-iteration", "500", "--n-steps", "500",
         "--batch-size", "100", "--n-epochs", "2", "--final-eval-episodes", "5",
         "--no-progress-bar", "--runs-root", str(tmp_path)]
    )  # fmt: skip
    returns = game.history[-1]["agent_returns"]
    assert returns["attacker"] == pytest.approx(-returns["defender"], abs=1e-9)
    assert returns["attacker"] > 0  # the attacker is paid a positive trace error
    learned = game.evaluations["defender (learned, vs the view's opponent)"]
    # a defender's score is the optimal Bayes cost over its own: in (0, 1]
    assert learned.score == pytest.approx(learned.reference / learned.mean, rel=1e-12)
    assert 0 < learned.score <= 1 + 1e-9


def test_an_iteration_that_samples_nothing_raises_naming_the_timeout():
    from agents.rllib import ZeroStepsSampled
    from agents.rllib.config import _Report

    report = _Report(single_agent="attacker", timeout=60.0)
    result = {"training_iteration": 1, "env_runners": {"num_env_steps_sampled": 0}}
    with pytest.raises(ZeroStepsSampled, match=r"sampled 0 env steps.*sample_timeout_s=60.0"):
        report(result=result)
    ok = {"env_runners": {"num_env_steps_sampled": 1000, "episode_return_mean": 0.03}}
    report(result=ok)
    assert ok["agent_returns"] == {"attacker": 0.03}  # the view's player, not "default_agent"


# ---------------------------------------------------------------------------- --resume

TINY_RUN = ["--n-steps", "200", "--batch-size", "100", "--n-epochs", "1",
            "--final-eval-episodes", "2", "--no-progress-bar", "--num-cpus", "2"]  # fmt: skip


class Evil:
    """Unpickling it creates ``marker`` (what a crafted pickle in a run folder could do)."""

    def __init__(self, marker) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        import pathlib

        return (pathlib.Path.touch, (pathlib.Path(self.marker),))


@pytest.fixture(scope="module")
def one_iteration_run(local_ray, tmp_path_factory):
    """A finished 1-iteration RLlib attacker run (200-step train batch); copy it to change it."""
    import train

    root = tmp_path_factory.mktemp("rllib_runs")
    result = train.main(
        ["attacker", "--backend", "rllib", "--total-timesteps", "200", *TINY_RUN,
         "--runs-root", str(root)]
    )  # fmt: skip
    return result


def _copy_run(result, tmp_path):
    import shutil

    dst = tmp_path / "runs" / result.run_dir.name
    shutil.copytree(result.run_dir, dst)
    (dst / ".lock").unlink(missing_ok=True)
    return dst


def test_state_round_trip_restores_weights_optimizer_kl_and_the_lr_schedule(local_ray, tmp_path):
    import torch

    from agents.rllib.config import ppo_config
    from agents.rllib.state import module_weights, read_state, restore_state, save_state

    def build(seed):
        return ppo_config(
            "fdia_env/SparseAttack-v0", {"scenario": "ch4-position"},
            hp=Hyperparameters(n_steps=200, batch_size=100, n_epochs=1),
            total_timesteps=2000, seed=seed,
        ).build_algo()  # fmt: skip

    first = build(0)
    try:
        s1 = first.train()["env_runners"]["num_env_steps_sampled"]
        save_state(first, tmp_path, {"timesteps": int(s1)})
        saved_w = module_weights(first, "default_policy")
        learner = first.learner_group._learner
        (opt,) = learner._named_optimizers.values()
        saved_opt = opt.state_dict()["state"]  # per parameter index: Adam's step and moments
        assert len(saved_opt) == 8 and float(saved_opt[0]["step"]) > 0
        saved_kl = float(learner.curr_kl_coeffs_per_module["default_policy"])
    finally:
        first.stop()
    second = build(7)
    try:
        fresh = module_weights(second, "default_policy")
        assert not all(torch.equal(fresh[k], v) for k, v in saved_w.items())  # test premise
        meta, payload = read_state(tmp_path)
        restore_state(second, meta, payload, tmp_path)
        for got in (module_weights(second, "default_policy"), second.get_module().state_dict()):
            for k, v in got.items():  # learner and (inference-only) env-runner module
                assert torch.equal(v, saved_w[k]), k
        learner = second.learner_group._learner
        (opt,) = learner._named_optimizers.values()
        got_opt = opt.state_dict()["state"]
        assert sorted(got_opt) == sorted(saved_opt)
        for i, st in saved_opt.items():
            for k, v in st.items():
                assert torch.equal(got_opt[i][k], v), (i, k)
        assert float(learner.curr_kl_coeffs_per_module["default_policy"]) == saved_kl
        assert second.iteration == 1
        # the linear schedule 1e-3 -> 0 over 2000 steps continues from the saved step count
        assert opt.param_groups[0]["lr"] == pytest.approx(1e-3 * (1 - s1 / 2000), rel=1e-6)
        result = second.train()
        s2 = result["env_runners"]["num_env_steps_sampled"]
        assert result["training_iteration"] == 2
        lr = result["learners"]["default_policy"]["default_optimizer_learning_rate"]
        assert lr == pytest.approx(1e-3 * (1 - (s1 + s2) / 2000), rel=1e-6)
    finally:
        second.stop()


def test_resume_continues_counters_from_the_saved_weights_and_never_reads_pickles(
    one_iteration_run, tmp_path, monkeypatch
):
    import torch

    import agents.rllib.state as state_module
    import train

    run_dir = _copy_run(one_iteration_run, tmp_path)
    marker = tmp_path / "pwned"
    pickles = sorted((run_dir / "checkpoint").rglob("*.pkl"))  # RLlib's own checkpoint
    assert pickles  # test premise: the run folder holds RLlib's pickles
    for path in pickles:
        path.write_bytes(pickle.dumps(Evil(marker)))
    saved = torch.load(run_dir / "rllib_state.pt", weights_only=True)["state_dicts"]
    restored = {}
    real_restore = state_module.restore_state

    def spy(algo, meta, payload, source):
        real_restore(algo, meta, payload, source)
        restored.update(state_module.module_weights(algo, "default_policy"))

    monkeypatch.setattr(state_module, "restore_state", spy)
    steps1 = one_iteration_run.timesteps
    more = train.main(
        ["attacker", "--backend", "rllib", "--resume", "--total-timesteps", str(steps1 + 1),
         "--no-progress-bar", "--runs-root", str(tmp_path / "runs")]
    )  # fmt: skip
    assert not marker.exists()
    assert more.run_dir == run_dir and more.resumed
    assert set(restored) == set(saved["rl_module/default_policy"])
    for k, v in saved["rl_module/default_policy"].items():
        assert torch.equal(restored[k], v), k  # before training went on
    assert [h["iteration"] for h in more.history] == [1, 2]
    steps = [h["timesteps"] for h in more.history]
    assert steps[0] == steps1 and steps1 < steps[1] == more.timesteps <= steps1 + 256
    assert more.train_seconds >= one_iteration_run.train_seconds
    scores = json.loads((run_dir / "scores.json").read_text())
    assert scores["iterations"] == 2 and scores["timesteps"] == steps[1] and scores["resumed"]
    state = json.loads((run_dir / "rllib_state.json").read_text())
    assert state["timesteps"] == steps[1] and state["iteration"] == 2 and state["records"] == 2
    lifetime = state["lifetime_stats"]["env_runners--num_env_steps_sampled_lifetime"]
    assert lifetime["lifetime_sum"] == steps[1]  # RLlib's own counter continued, too
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == [run_dir.name]


def test_a_pickle_in_the_state_tensor_file_is_refused_even_when_trusted(
    one_iteration_run, tmp_path, capsys
):
    import hashlib

    import torch

    import train

    run_dir = _copy_run(one_iteration_run, tmp_path)
    marker = tmp_path / "pwned"
    tensors = run_dir / "rllib_state.pt"
    torch.save({"state_dicts": {"rl_module/default_policy": Evil(marker)}, "variables": {}},
               tensors)  # fmt: skip
    state = json.loads((run_dir / "rllib_state.json").read_text())
    state["sha256"] = hashlib.sha256(tensors.read_bytes()).hexdigest()  # a consistent forgery
    (run_dir / "rllib_state.json").write_text(json.dumps(state))
    for extra in ([], ["--trust-checkpoint"]):
        code = train.cli(
            ["attacker", "--backend", "rllib", "--resume", "--run-dir", str(run_dir),
             "--total-timesteps", "1000", *extra]
        )  # fmt: skip
        err = capsys.readouterr().err
        assert code == 2
        assert "is not a weights-only torch file and was not loaded" in err
        assert not marker.exists()
    data = bytearray(tensors.read_bytes())
    data[-1] ^= 1
    tensors.write_bytes(bytes(data))  # changed after its SHA-256 was recorded
    assert train.cli(["attacker", "--backend", "rllib", "--resume", "--run-dir", str(run_dir)]) == 2
    assert "does not match the SHA-256" in capsys.readouterr().err


def test_resume_without_a_saved_state_names_what_is_missing(tmp_path, capsys):
    import train

    assert train.cli(["attacker", "--backend", "rllib", "--resume",
                      "--runs-root", str(tmp_path)]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "nothing to resume" in err and "rllib_state.json" in err
    assert "sparse_attack_v2-rllib-PPO-s0" in err


def test_a_run_stopped_before_its_first_state_starts_again_from_step_0(
    one_iteration_run, tmp_path, capsys
):
    import os
    import shutil

    import train

    run_dir = _copy_run(one_iteration_run, tmp_path)
    for name in os.listdir(run_dir):  # what a kill before the first state leaves
        if name not in ("config.json", ".lock"):
            path = run_dir / name
            shutil.rmtree(path) if path.is_dir() else path.unlink()
    capsys.readouterr()
    result = train.main(["attacker", "--backend", "rllib", "--resume", "--run-dir", str(run_dir)])
    out = capsys.readouterr().out
    assert f"resuming {run_dir}: it has no checkpoint" in out
    assert "training starts again from step 0" in out
    assert result.run_dir == run_dir and (run_dir / "rllib_state.json").is_file()
    assert result.timesteps == one_iteration_run.timesteps


def test_sigint_stops_after_the_iteration_and_leaves_a_resumable_state(local_ray, tmp_path, capsys):
    import os
    import signal
    import threading
    import time

    import train
    from agents.rllib.state import read_state

    def watch():
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            if list((tmp_path / "runs").glob("*/progress.jsonl")):
                os.kill(os.getpid(), signal.SIGINT)
                return
            time.sleep(0.05)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    code = train.cli(
        ["attacker", "--backend", "rllib", "--total-timesteps", "100000000", *TINY_RUN,
         "--runs-root", str(tmp_path / "runs")]
    )  # fmt: skip
    thread.join()
    err = capsys.readouterr().err
    assert code == 130
    (run_dir,) = (tmp_path / "runs").iterdir()
    meta, _ = read_state(run_dir)
    progress = [json.loads(line) for line in (run_dir / "progress.jsonl").read_text().splitlines()]
    scores = json.loads((run_dir / "scores.json").read_text())
    assert 1 <= meta["records"] == len(progress) == scores["iterations"] == meta["iteration"]
    assert 0 < meta["timesteps"] == progress[-1]["timesteps"] == scores["timesteps"] < 10**8
    assert scores["interrupted"] == signal.SIGINT
    assert err.strip().splitlines()[-1] == (
        f"train.py: stopped by SIGINT after {meta['timesteps']} steps; state and scores saved "
        f"in {run_dir}; continue with: python train.py attacker --backend rllib --resume "
        f"--run-dir {run_dir}"
    )


def test_psro_resume_rebuilds_earlier_policies_from_weights_only_files(
    local_ray, tmp_path, monkeypatch, capsys
):
    import torch

    import train
    from agents.config import SCENARIO_DEFAULTS, ScenarioDefaults
    from baselines.game import exploitability, payoff_matrix
    from fdia_env import sensor_game_v0

    args = ["game", "--backend", "rllib", "--method", "psro", "--steps-per-iteration", "200",
            "--no-progress-bar", "--runs-root", str(tmp_path)]  # fmt: skip
    tiny = ["--n-steps", "200", "--batch-size", "100", "--n-epochs", "1",
            "--final-eval-episodes", "2"]  # fmt: skip
    first = train.main([*args, *tiny, "--iterations", "1"])
    meta1 = json.loads((first.run_dir / "scores.json").read_text())["meta_payoff"]
    # train.py's defaults for the game changed since the run was saved: the resume plays the
    # run's own game (the independent allocation the payoffs below are checked against)
    key = ("sensor_game_v0", "ch5-game")
    assert key not in SCENARIO_DEFAULTS
    today = ScenarioDefaults(env_kwargs={"allocation": "dependent"})
    monkeypatch.setitem(SCENARIO_DEFAULTS, key, today)
    capsys.readouterr()
    more = train.main([*args, "--resume", "--iterations", "2"])
    assert "resuming with the run's own env options" in capsys.readouterr().out
    assert more.run_dir == first.run_dir
    assert [h["iteration"] for h in more.history] == [1, 2]
    assert [h["timesteps"] for h in more.history] == [400, 800]
    scores = json.loads((more.run_dir / "scores.json").read_text())
    meta = np.array(scores["meta_payoff"])
    assert meta.shape == (2, 2) and meta[0, 0] == meta1[0][0]
    # one-shot game, deterministic policies: each meta entry is the payoff of the pure pair; the
    # new row and column were played against the earlier policies rebuilt from their files
    pops = scores["populations"]
    p = sensor_game_v0.parallel_env(scenario="ch5-game")
    L = payoff_matrix(p.scenario, p.attack.power, p.attack.allocation)
    for i in range(2):
        for j in range(2):
            assert meta[i, j] == pytest.approx(L[pops["defender"][i], pops["attacker"][j]],
                                               rel=1e-9)  # fmt: skip
    e = exploitability(L, more.x, more.y, more.value)
    assert more.history[-1]["nash_conv"] == pytest.approx(e.nash_conv, rel=1e-12)
    state = json.loads((more.run_dir / "rllib_state.json").read_text())
    for side in ("attacker", "defender"):
        for record in state["policies"][side]:
            payload = torch.load(more.run_dir / "policies" / record["file"], weights_only=True)
            assert set(payload) == {"state_dicts", "variables"}


def test_resume_with_other_options_lists_each_difference(one_iteration_run, tmp_path, capsys):
    import train

    run_dir = _copy_run(one_iteration_run, tmp_path)
    code = train.cli(["attacker", "--backend", "rllib", "--resume", "--run-dir", str(run_dir),
                      "--n-steps", "300", "--ent-coef", "0.01"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2
    assert "options differ from its config.json" in err
    assert "n-steps: saved 200, given 300" in err and "ent-coef: saved None, given 0.01" in err
    assert not (run_dir / "progress.jsonl").read_text().count("\n") > 1  # nothing trained


def test_resume_keeps_the_runs_own_env_options_when_the_defaults_changed(
    one_iteration_run, tmp_path, capsys, monkeypatch
):
    # train.py's per-scenario defaults change between versions; a resume trains on the env
    # options the run was resolved with (as the SB3 and torch-ppo drivers do), and says so
    import json

    import train
    from agents.config import SCENARIO_DEFAULTS, ScenarioDefaults
    from agents.registry import get

    run_dir = _copy_run(one_iteration_run, tmp_path)
    saved = json.loads((run_dir / "config.json").read_text())["resolved"]
    assert saved["env"] == get("sparse_attack_v2", "attacker").gym_id  # the run's env
    key = ("sparse_attack_v2", saved["env_kwargs"]["scenario"])
    assert key not in SCENARIO_DEFAULTS and "reward_mode" not in saved["env_kwargs"]
    monkeypatch.setitem(
        SCENARIO_DEFAULTS, key, ScenarioDefaults(env_kwargs={"reward_mode": "shaped"})
    )
    steps = one_iteration_run.timesteps
    more = train.main(
        ["attacker", "--backend", "rllib", "--resume", "--run-dir", str(run_dir),
         "--total-timesteps", str(steps + 1), "--no-progress-bar"]
    )  # fmt: skip
    assert more.resumed
    out = capsys.readouterr().out
    assert "resuming with the run's own env options" in out and "'reward_mode': 'shaped'" in out
    resumed = json.loads((run_dir / "config.json").read_text())["resolved"]
    assert resumed["env_kwargs"] == saved["env_kwargs"]


# RLlib's masked PPO module on the sequential action format: one small PPO iteration of the
# sensor game's two masked players, and of the sparse attacker in the plan-first order
# (sparse_attack_v2's default: Discrete(N·M + 1) pairs, then the plan plays out) and in its
# order="increasing" (the picks in increasing order: the mask closes the pairs below) and with
# its state groups, with illegal_action="error", so a single action outside a mask would stop
# the test
@pytest.mark.parametrize(
    ("name", "env_config", "policies", "mask_size"),
    [
        ("sensor_game_v0", {"rounds": 2}, {"attacker", "defender"}, 4),  # M + 1, M = 3
        ("sparse_attack_v2", {"budget": 2, "horizon": 2}, {"attacker"}, 7),  # N·M + 1 = 2·3 + 1
        ("sparse_attack_v2", {"budget": 2, "horizon": 2, "order": "increasing"}, {"attacker"}, 7),
        # the state groups: N·n = 2·2 more actions
        ("sparse_attack_v2", {"budget": 2, "horizon": 2, "groups": "state"}, {"attacker"}, 11),
    ],
)
def test_plain_ppo_config_trains_on_the_sequential_format_within_the_mask(
    local_ray, name, env_config, policies, mask_size
):
    from ray.rllib.algorithms.ppo import PPOConfig

    from agents.rllib.envs import register_envs
    from agents.rllib.module import MaskedPPOTorchRLModule

    register_envs()
    config = (
        PPOConfig()
        # RLlib's env pre-check steps with unmasked samples of the action space, which
        # illegal_action="error" refuses whenever a sample falls outside the mask (the test is
        # about the learner's actions, which the masked module keeps inside it)
        .environment(
            name, env_config={**env_config, "action": "sequential"}, disable_env_checking=True
        )
        .env_runners(num_env_runners=0)
        .training(train_batch_size_per_learner=64, minibatch_size=64, num_epochs=1)
    )
    config.env_config["illegal_action"] = "error"
    if policies is not None:
        config = config.multi_agent(
            policies=policies, policy_mapping_fn=lambda agent_id, *a, **k: agent_id
        )
    algo = config.build_algo()
    try:
        result = algo.train()
        assert result["env_runners"]["num_env_steps_sampled"] >= 64
        for module_id in policies or ["default_policy"]:
            module = algo.get_module(module_id)
            assert isinstance(module, MaskedPPOTorchRLModule) and module._keys is not None
            assert module.observation_space["action_mask"].shape == (mask_size,)
    finally:
        algo.stop()
