"""The one population loop (IBR, FSP, PSRO) with the exact best-response oracle."""

import json
import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py lives at the root

import train
from agents.population import (
    SIDES,
    ConstantPolicy,
    ExactOracle,
    MatrixGame,
    PopulationState,
    run_population,
)
from agents.registry import get
from baselines.game import exploitability, payoff_matrix, solve_zero_sum


@pytest.fixture(scope="module")
def game():
    """The sensor game (ch5-game, 7 x 7) with its exact payoff matrix and value."""
    entries = {side: get("sensor_game_v0", side) for side in SIDES}
    kwargs = entries["attacker"].env_kwargs(None)
    with entries["attacker"].make(**kwargs) as env:
        reference = entries["attacker"].reference_of(env)
    return MatrixGame(entries, kwargs, reference.matrix_game(), reference.value)


def run(game, method, iterations, state=None, oracle=None):
    state = state or PopulationState.new(game.sizes)
    oracle = oracle or ExactOracle(game.payoff)
    return run_population(method, oracle, game, state, iterations, seed=0), state


def test_psro_with_exact_answers_is_the_double_oracle_and_reaches_the_equilibrium(game):
    history, state = run(game, "psro", 6)
    nash_conv = [h["relative_nash_conv"] for h in history]
    assert nash_conv[:3] == pytest.approx([0.9191, 1.0702, 0.2271], abs=1e-4)
    assert max(nash_conv[3:]) <= 1e-12  # the support is found at iteration 4
    x, y = state.x, state.y
    assert x @ game.payoff @ y == pytest.approx(game.value, rel=1e-12)
    e = exploitability(game.payoff, x, y, game.value)
    assert e.nash_conv == pytest.approx(0.0, abs=1e-9 * game.value)
    # the meta-game played in the env equals the matrix on the populations' actions
    rows, cols = state.actions["defender"], state.actions["attacker"]
    np.testing.assert_allclose(state.meta, game.payoff[np.ix_(rows, cols)], rtol=1e-9)
    assert solve_zero_sum(state.meta)[2] == pytest.approx(game.value, rel=1e-9)


def test_ibr_cycles_and_every_exact_answer_has_zero_gap(game):
    history, _ = run(game, "ibr", 8)
    attacker = [h["br_attacker"] for h in history]
    defender = [h["br_defender"] for h in history]
    assert attacker == [0, 1, 1, 0, 0, 1, 1, 0] and defender == [5, 5, 4, 4, 5, 5, 4, 4]
    assert all(h["br_gap_attacker"] == h["br_gap_defender"] == 0.0 for h in history)
    assert history[4]["nash_conv"] == history[0]["nash_conv"] > 0  # period 4: no convergence


def test_fsp_averages_its_answers_and_its_exploitability_falls(game):
    history, state = run(game, "fsp", 12)
    nash_conv = [h["relative_nash_conv"] for h in history]
    assert nash_conv[0] == pytest.approx(0.9191, abs=1e-4)
    assert nash_conv[-1] < 0.13 and nash_conv[-1] < nash_conv[0] / 7
    counts = np.bincount(state.actions["attacker"], minlength=game.sizes["attacker"])
    np.testing.assert_allclose(state.y, counts / 12)  # the uniform mix over the population
    assert [h["timesteps"] for h in history] == [0] * 12  # exact answers take no env steps


def test_a_resumed_loop_continues_as_if_never_stopped(game):
    straight, _ = run(game, "psro", 6)
    _, first = run(game, "psro", 2)
    saved = json.loads(json.dumps({**first.saved(), "history": first.history}))  # state.json
    # PSRO's meta-game needs the earlier policies back (here: pure strategies)
    policies = {side: [ConstantPolicy(a) for a in saved["populations"][side]] for side in SIDES}
    state = PopulationState(
        saved["populations"],
        policies,
        saved["policies"],
        np.array(saved["meta_payoff"]),
        np.array(saved["x"]),
        np.array(saved["y"]),
        saved["history"],
    )
    resumed, _ = run(game, "psro", 6, state)
    drop = ("train_seconds",)
    assert [{k: v for k, v in h.items() if k not in drop} for h in resumed] == [
        {k: v for k, v in h.items() if k not in drop} for h in straight
    ]


class StopsAt:
    """The exact oracle, cut short (None) for ``side`` in ``iteration``: a stop request."""

    def __init__(self, payoff, side, iteration):
        self.inner, self.side, self.iteration = ExactOracle(payoff), side, iteration
        self.saved = []

    def learn(self, side, opponent, iteration):
        if (side, iteration) == (self.side, self.iteration):
            return None
        return self.inner.learn(side, opponent, iteration)

    def save(self, side, index, response):
        self.saved.append((side, index))
        return self.inner.save(side, index, response)


def test_an_answer_cut_short_drops_its_iteration(game):
    oracle = StopsAt(game.payoff, "defender", 3)
    history, state = run(game, "fsp", 6, oracle=oracle)
    assert [h["iteration"] for h in history] == [1, 2]
    assert {side: len(state.actions[side]) for side in SIDES} == {"attacker": 2, "defender": 2}
    assert oracle.saved == [("attacker", 0), ("defender", 0), ("attacker", 1), ("defender", 1)]


def test_unknown_methods_are_refused(game):
    with pytest.raises(ValueError, match="unknown method 'dqn'; valid methods: psro, fsp, ibr"):
        run(game, "dqn", 1)


# ---------------------------------------------------------------------------- train.py game


def run_game(tmp_path, *args):
    return train.main(
        ["game", *args, "--no-progress-bar", "--final-eval-episodes", "20",
         "--runs-root", str(tmp_path / "runs")]
    )  # fmt: skip


def test_the_game_command_runs_the_exact_oracle_and_resumes_it(tmp_path):
    first = run_game(tmp_path, "--method", "psro", "--algo", "exact", "--iterations", "3")
    assert first.run_dir.name.startswith("sensor_game_v0-psro-exact-s0-")
    assert [h["timesteps"] for h in first.history] == [0, 0, 0]  # nothing learned
    state = json.loads((first.run_dir / "state.json").read_text())
    assert state["policies"] == state["populations"]  # a pure strategy is its own record
    more = run_game(
        tmp_path, "--method", "psro", "--algo", "exact", "--iterations", "5", "--resume"
    )
    assert more.run_dir == first.run_dir and len(more.history) == 5
    assert more.history[:3] == first.history
    assert more.history[-1]["relative_nash_conv"] <= 1e-12
    with pytest.raises(ValueError, match=r"--algo exact .* --learning-rate do"):
        run_game(tmp_path, "--algo", "exact", "--learning-rate", "0.1", "--run-dir", "x")


def test_a_game_killed_before_its_first_state_starts_again_from_iteration_0(tmp_path, capsys):
    first = run_game(tmp_path, "--method", "psro", "--algo", "exact", "--iterations", "3")
    for name in os.listdir(first.run_dir):  # what a kill before the first state leaves
        if name not in ("config.json", ".lock"):
            path = first.run_dir / name
            shutil.rmtree(path) if path.is_dir() else path.unlink()
    capsys.readouterr()
    again = run_game(
        tmp_path, "--method", "psro", "--algo", "exact", "--iterations", "3", "--resume"
    )
    out = capsys.readouterr().out
    assert f"resuming {first.run_dir}: it has no checkpoint" in out
    assert "training starts again from step 0" in out

    def played(history):
        return [{k: v for k, v in h.items() if k != "train_seconds"} for h in history]

    assert again.run_dir == first.run_dir and played(again.history) == played(first.history)


def test_a_game_resume_plays_the_runs_own_game_when_the_defaults_changed(
    tmp_path, monkeypatch, capsys
):
    # train.py's per-scenario defaults change between versions; a resumed game keeps the env
    # options (and so the payoff matrix) its run was resolved with, and says so
    from agents.config import SCENARIO_DEFAULTS, ScenarioDefaults

    first = run_game(tmp_path, "--method", "psro", "--algo", "exact", "--iterations", "2")
    saved = json.loads((first.run_dir / "config.json").read_text())["resolved"]
    key = ("sensor_game_v0", saved["env_kwargs"]["scenario"])
    assert key not in SCENARIO_DEFAULTS and "allocation" not in saved["env_kwargs"]
    today = ScenarioDefaults(env_kwargs={"allocation": "dependent"})
    monkeypatch.setitem(SCENARIO_DEFAULTS, key, today)
    capsys.readouterr()
    more = run_game(
        tmp_path, "--method", "psro", "--algo", "exact", "--iterations", "3", "--resume"
    )
    out = capsys.readouterr().out
    assert "resuming with the run's own env options" in out and "'dependent'" in out
    assert more.history[:2] == first.history and more.value == pytest.approx(first.value)
    resumed = json.loads((more.run_dir / "config.json").read_text())["resolved"]
    assert resumed["env_kwargs"] == saved["env_kwargs"]


def test_a_game_resume_trains_with_the_runs_own_hyperparameters_when_the_defaults_changed(
    tmp_path, monkeypatch, capsys
):
    # as the attacker and defender commands: a resumed game's learners keep the
    # hyperparameters its run was resolved with, not train.py's scenario table of today
    from agents.config import SCENARIO_DEFAULTS, ScenarioDefaults

    args = ["--method", "psro", "--algo", "torch-ppo", "--device", "cpu",
            "--steps-per-iteration", "768"]  # fmt: skip
    first = run_game(tmp_path, *args, "--iterations", "1")
    saved = json.loads((first.run_dir / "config.json").read_text())["resolved"]
    key = ("sensor_game_v0", saved["env_kwargs"]["scenario"])
    assert key not in SCENARIO_DEFAULTS and saved["hyperparameters"]["ent_coef"] != 0.123
    today = ScenarioDefaults(hyperparameters={"ent_coef": 0.123})
    monkeypatch.setitem(SCENARIO_DEFAULTS, key, today)
    capsys.readouterr()
    more = run_game(tmp_path, *args, "--iterations", "2", "--resume")
    out = capsys.readouterr().out
    assert "resuming with the run's own hyperparameters {'ent_coef'" in out and "0.123" in out
    assert more.history[:1] == first.history and len(more.history) == 2
    resumed = json.loads((more.run_dir / "config.json").read_text())["resolved"]
    assert resumed["hyperparameters"] == saved["hyperparameters"]
    # a new run takes today's table
    fresh = run_game(tmp_path, *args, "--iterations", "1", "--seed", "1")
    new = json.loads((fresh.run_dir / "config.json").read_text())["resolved"]
    assert new["hyperparameters"]["ent_coef"] == 0.123


def test_the_game_command_runs_torch_ppo_best_responses_and_resumes_them(tmp_path):
    args = ["--method", "psro", "--algo", "torch-ppo", "--device", "cpu",
            "--steps-per-iteration", "768"]  # fmt: skip
    first = run_game(tmp_path, *args, "--iterations", "2")
    assert first.run_dir.name.startswith("sensor_game_v0-psro-torch-ppo-s0-")
    assert [h["timesteps"] for h in first.history] == [1536, 3072]
    names = sorted(p.name for p in (first.run_dir / "policies").iterdir())
    assert names == [f"{side}_{k}.{ext}" for side in ("attacker", "defender") for k in (0, 1)
                     for ext in ("json", "pt")]  # fmt: skip
    more = run_game(tmp_path, *args, "--iterations", "3", "--resume")
    assert more.history[:2] == first.history and len(more.history) == 3
    # the meta-game grew from the reloaded policies: each entry is the payoff of their actions
    state = json.loads((more.run_dir / "state.json").read_text())
    rows, cols = state["populations"]["defender"], state["populations"]["attacker"]
    L = payoff_matrix("ch5-game")
    np.testing.assert_allclose(state["meta_payoff"], L[np.ix_(rows, cols)], rtol=1e-9)


def test_the_learned_oracles_share_their_seeds_and_policy_files(tmp_path):
    """SB3, torch-ppo and RLlib answers: one seed per (side, iteration), one file per policy."""
    from types import SimpleNamespace

    from agents.interrupt import StopRequest
    from agents.population import LearnedOracle
    from agents.rllib.train import RLlibOracle
    from agents.seeding import derived_seed
    from agents.selfplay import SB3Oracle, TorchPPOOracle

    cfg = SimpleNamespace(run=SimpleNamespace(seed=7, device="cpu"))
    stop = StopRequest()
    oracles = [
        SB3Oracle(cfg, tmp_path, {}, {}, "ppo", {}, {}, stop),
        TorchPPOOracle(cfg, tmp_path, {}, {}, None, stop),
        RLlibOracle(cfg, tmp_path, {}, {}),
    ]
    seeds = {(s, k): derived_seed(7, 1000 * k + SIDES.index(s)) for s in SIDES for k in range(3)}
    assert len(set(seeds.values())) == 6  # every answer its own seed
    for oracle in oracles:
        assert isinstance(oracle, LearnedOracle)
        assert {key: oracle.seed(*key) for key in seeds} == seeds
        assert oracle.policy_path("defender", 4) == tmp_path / "policies" / "defender_4.json"
    assert oracles[1].device == "cpu" and oracles[0].callback is not None
    assert oracles[2].policy_path("attacker", 0, ".pt").name == "attacker_0.pt"


# ------------------------------------------------------- expected rewards over the opponent mix


@pytest.mark.parametrize("action", ["subset", "sequential"])
@pytest.mark.parametrize("side", SIDES)
def test_the_expected_opponent_env_pays_the_mix_s_exact_expected_payoff(side, action):
    """Every learner action's reward is Σ_j p_j L[., j] (defender: −L), one copy per support."""
    from agents.selfplay import ExpectedOpponentEnv
    from fdia_env.envs.sequential import subset_actions

    L = payoff_matrix("ch5-game")  # 7 x 7, defender rows
    kwargs = {**get("sensor_game_v0", side).env_kwargs(None), "action": action}
    probs = np.array([0.5, 0.0, 0.2, 0.0, 0.0, 0.3, 0.0])
    env = ExpectedOpponentEnv(get("sensor_game_v0", side).gym_id, kwargs, probs)
    assert len(env.copies) == 3 and env.weights.tolist() == [0.5, 0.2, 0.3]
    expected = -(L @ probs) if side == "defender" else probs @ L
    for own in range(7):
        env.reset(seed=own)
        if action == "subset":
            steps = [own]
        else:  # the subset built one sensor per decision, then stop
            seq = env.copies[0].unwrapped
            subset = seq.parallel.models[side].subsets[own]
            # then stop, and wait (stop) until the opponent of every copy has stopped
            steps = [*subset_actions(seq.parallel, side, subset), *[0] * 4]
        total, done = 0.0, False
        for a in steps:
            _, reward, terminated, truncated, _ = env.step(a)
            total, done = total + reward, terminated or truncated
            if done:
                break
        assert done
        assert total == pytest.approx(expected[own], rel=1e-12, abs=1e-15)
    # every strategy played is recorded with its exact value; the best one wins over a candidate
    assert sorted(env.values) == list(range(7))
    np.testing.assert_allclose([env.values[a] for a in range(7)], expected, rtol=1e-12)
    best = int(np.argmax(expected))
    assert env.best_strategy(best) == best and env.best_strategy((best + 1) % 7) == best
    env.values = {}
    assert env.value_of(3) == pytest.approx(expected[3], rel=1e-12)
    assert env.best_strategy(3) == 3  # nothing better played
    env.close()
    with pytest.raises(ValueError, match="opponent must be a 1-D mix"):
        ExpectedOpponentEnv(get("sensor_game_v0", side).gym_id, kwargs, -probs)


def test_expected_rewards_default_to_the_scenario_s_and_apply_to_sb3_only():
    from agents.config import GameConfig
    from agents.selfplay import expected_rewards

    assert expected_rewards(GameConfig(scenario="grid-ieee14"), "MaskablePPO") is True
    assert expected_rewards(GameConfig(scenario="game-m10"), "PPO") is False
    assert expected_rewards(GameConfig(), "PPO") is False
    assert expected_rewards(GameConfig(expected_rewards=True), "PPO") is True
    assert expected_rewards(GameConfig(scenario="grid-ieee14", expected_rewards=False), "PPO") is (
        False
    )
    assert expected_rewards(GameConfig(scenario="grid-ieee14"), "exact") is False
    with pytest.raises(ValueError, match=r"--expected-rewards applies to SB3 .* not --algo exact"):
        expected_rewards(GameConfig(expected_rewards=True), "exact")
    with pytest.raises(
        TypeError, match=r"expected_rewards \(--expected-rewards\) must be true or false"
    ):
        GameConfig(expected_rewards="yes")


def test_a_best_response_learned_on_expected_rewards_is_exact(game):
    """PPO paid the expected reward over a 3-strategy mix answers it exactly on ch5-game."""
    import torch

    from agents.config import Hyperparameters, algo_kwargs
    from agents.selfplay import learn_best_response

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # small networks: one thread (as the game command's runs)
    mix = np.array([0.5, 0.0, 0.2, 0.0, 0.0, 0.3, 0.0])
    kwargs = algo_kwargs("PPO", Hyperparameters(n_steps=64, batch_size=32))
    _, action = learn_best_response(
        game.entries["defender"], game.env_kwargs, mix, "PPO", kwargs, 512, seed=0, expected=True
    )
    torch.set_num_threads(threads)
    losses = game.payoff @ mix
    assert losses[action] == losses.min()
    assert np.sort(losses)[1] > losses.min() * 1.05  # a unique answer, 5 % better than the next


def test_the_game_command_trains_on_expected_rewards(tmp_path):
    run = run_game(tmp_path, "--method", "psro", "--algo", "PPO", "--iterations", "1",
                   "--steps-per-iteration", "64", "--n-steps", "64", "--batch-size", "64",
                   "--expected-rewards", "True")  # fmt: skip
    config = json.loads((run.run_dir / "config.json").read_text())
    assert config["resolved"]["expected_rewards"] is True
    assert [h["timesteps"] for h in run.history] == [128]


def test_a_game_resume_keeps_the_runs_own_expected_rewards_when_the_default_changed(
    tmp_path, monkeypatch, capsys
):
    # the scenario table of expected rewards (GAME_EXPECTED_REWARDS) may change between
    # versions; a resumed game's SB3 best responses keep what the run was resolved with
    import agents.selfplay

    args = ["--method", "psro", "--algo", "PPO", "--scenario", "ch5-game",
            "--steps-per-iteration", "64", "--n-steps", "64", "--batch-size", "64"]  # fmt: skip
    first = run_game(tmp_path, *args, "--iterations", "1")
    saved = json.loads((first.run_dir / "config.json").read_text())["resolved"]
    assert saved["expected_rewards"] is False
    monkeypatch.setattr(agents.selfplay, "GAME_EXPECTED_REWARDS", ("ch5-game",))
    capsys.readouterr()
    more = run_game(tmp_path, *args, "--iterations", "2", "--resume")
    out = capsys.readouterr().out
    assert "resuming with the run's own expected rewards False" in out
    resumed = json.loads((more.run_dir / "config.json").read_text())["resolved"]
    assert resumed["expected_rewards"] is False and len(more.history) == 2
    assert resumed["reward_scale"] == saved["reward_scale"]
    fresh = run_game(tmp_path, *args, "--iterations", "1", "--seed", "1")  # today's default
    assert json.loads((fresh.run_dir / "config.json").read_text())["resolved"]["expected_rewards"]


def test_the_sequential_format_s_meta_game_plays_both_pure_strategies(game):
    """PSRO's meta-game in the sequential format holds L's entries of the populations' subsets."""
    sequential = MatrixGame(
        game.entries, {**game.env_kwargs, "action": "sequential"}, game.payoff, game.value
    )
    _, state = run(sequential, "psro", 4)
    rows, cols = state.actions["defender"], state.actions["attacker"]
    np.testing.assert_allclose(state.meta, game.payoff[np.ix_(rows, cols)], rtol=1e-12)
    assert state.history[-1]["relative_nash_conv"] <= 1e-12  # the double oracle's equilibrium
