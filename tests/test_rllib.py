"""RLlib backend (agents.rllib): env forms, config, one iteration of each kind, a Tune sweep.

Needs the fdia-env[rllib] extra (skipped without it; tests/test_rllib_cli.py runs without).
One local Ray with 2 CPUs serves the module; each test trains one PPO iteration of 500-1,000
steps.
"""

from __future__ import annotations

import json
import math

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
