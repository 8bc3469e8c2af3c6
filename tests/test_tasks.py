"""The benchmark tasks: registry, stored references, normalised score, grading."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from agents.bench.verify import CHEAP_SECONDS, compare, stored_seconds
from agents.evaluate import evaluate
from fdia_env import tasks
from fdia_env.tasks.task import GAP_HARD, HEURISTIC_HARD, RANDOM_HARD

ALL = list(tasks.TASKS)


def test_every_defined_task_has_stored_references():
    assert tasks.pending() == []
    assert len(ALL) == len(tasks.SPECS)


@pytest.mark.parametrize("name", ALL)
def test_every_task_builds_and_steps(name):
    task = tasks.get(name)
    env = task.make_env()
    try:
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        masks = getattr(env.unwrapped, "action_masks", None)
        rng = np.random.default_rng(0)
        if masks is not None and isinstance(env.action_space, gym.spaces.Discrete):
            action = int(rng.choice(np.flatnonzero(masks())))
        else:
            env.action_space.seed(0)
            action = env.action_space.sample()
        _, reward, _, _, _ = env.step(action)
        assert math.isfinite(float(reward))
    finally:
        env.close()


def test_get_names_the_parameter_and_close_names():
    with pytest.raises(
        ValueError,
        match=r"task must be .*'sparse/ch4-positon-v0'.*close names: "
        r"sparse/ch4-position-v0",
    ):
        tasks.get("sparse/ch4-positon-v0")
    with pytest.raises(ValueError, match="task must be"):
        tasks.get(["not", "a", "name"])


def test_names_filters_and_refuses_unknown_filters():
    sparse = tasks.names(family="sparse")
    assert sparse and all(tasks.get(n).family == "sparse" for n in sparse)
    hard = tasks.names(difficulty="hard")
    assert all(tasks.get(n).difficulty == "hard" for n in hard)
    assert set(tasks.names()) == set(ALL)
    with pytest.raises(ValueError, match="difficulty must be one of"):
        tasks.names(difficulty="extreme")
    with pytest.raises(ValueError, match="family must be one of"):
        tasks.names(family="sparse-attack")


def test_normalise_refuses_non_numbers():
    task = tasks.get("sparse/ch4-position-v0")
    with pytest.raises(TypeError, match="raw must be a real number"):
        task.normalise("0.1")
    with pytest.raises(ValueError, match="raw must be finite"):
        task.normalise(float("nan"))
    with pytest.raises(ValueError, match="is not a game"):
        task.normalise_exploitability(0.0)


def test_the_exs_policy_played_in_the_env_scores_one_exactly():
    from baselines.sparse import exhaustive

    task = tasks.get("sparse/ch4-position-v0")
    kw = task.env_kwargs
    best = exhaustive(kw["scenario"], kw["budget"], kw["horizon"], kw["objective"])
    env = task.make_env()
    result = evaluate(best.policy(), env, n_episodes=2, reference=1.0)
    env.close()
    # the stored optimum and the env's return are both this EXS plan's Φ, each computed with the
    # machine's BLAS: equal to the last few ulps on any CPU (bit for bit on the one that stored it)
    assert task.normalise(result.mean) == pytest.approx(1.0, abs=1e-12)
    assert result.mean == pytest.approx(task.references.optimum.value, rel=1e-14)


def test_random_play_scores_zero_within_its_ci():
    task = tasks.get("sparse/ch4-position-v0")
    env = task.make_env()
    fresh = evaluate("random", env, n_episodes=200, seed=10_000, reference=1.0, num_envs=200)
    env.close()
    refs = task.references
    span = refs.optimum.value - refs.random.mean
    ci = (refs.random.ci95 + fresh.ci95) / span  # both means' CIs, in normalised units
    score = task.normalise(fresh.mean)
    assert score != 0.0  # other episodes than the stored ones
    assert abs(score) <= ci


def test_game_score_is_one_at_equilibrium_and_zero_for_uniform_play():
    from baselines.game import exploitability, payoff_matrix, solve_zero_sum

    task = tasks.get("sensor-game/ch5-game-attacker-v0")
    L = payoff_matrix("ch5-game", 100.0)
    x, y, v = solve_zero_sum(L)
    assert task.normalise_exploitability(exploitability(L, x, y, v).attacker) == pytest.approx(
        1.0, abs=1e-12
    )
    uniform = np.full(L.shape[1], 1.0 / L.shape[1])
    assert task.normalise_exploitability(
        exploitability(L, x, uniform, v).attacker
    ) == pytest.approx(0.0, abs=1e-12)


def test_hard_tasks_meet_the_criteria_on_their_stored_references():
    hard = tasks.names(difficulty="hard")
    for name in hard:
        refs = tasks.get(name).references
        assert refs.random_ratio <= RANDOM_HARD, name
        assert refs.heuristic_score is not None and refs.heuristic_score <= HEURISTIC_HARD, name
        assert refs.optimum.certified or refs.optimum.gap <= GAP_HARD, name


CHEAP = [n for n in ALL if stored_seconds(n) < CHEAP_SECONDS]


@pytest.mark.parametrize("name", CHEAP)
def test_cheap_references_recompute_equal(name):
    from agents.bench.references import compute

    assert compare(tasks.get(name).references, compute(tasks.spec(name))) == []


def test_command_line_refuses_an_unknown_task_and_reports_a_missing_score_module(
    monkeypatch, capsys
):
    import sys

    from agents.bench.__main__ import main

    assert main(["verify", "--task", "sparse/nope-v0"]) == 2
    assert "task must be a task name" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "agents.bench.score", None)  # as if it were not installed
    assert main(["score", "--task", "sparse/ch4-position-v0"]) == 2
    assert "agents.bench.score is not installed" in capsys.readouterr().err


def test_command_line_verify_runs_on_one_task(capsys):
    from agents.bench.__main__ import main

    assert main(["verify", "--task", "sensor-game/ch5-game-attacker-v0"]) == 0
    out = capsys.readouterr().out
    assert "sensor-game/ch5-game-attacker-v0" in out and "1/1 tasks match" in out


def test_the_benchmark_page_shows_the_stored_references():
    from pathlib import Path

    from agents.bench.verify import tasks_table

    page = (Path(__file__).resolve().parents[1] / "docs" / "benchmark.md").read_text("utf-8")
    assert tasks_table() in page  # rewrite it with: python -m agents.bench table
    assert page.count("| `") >= len(ALL)


@pytest.mark.parametrize("name", ["sparse/tracking-m6-1000007-v0", "covariance/ch2-pv-2-logdet-v0"])
def test_the_optimal_policy_of_a_hard_task_scores_one(name):
    from baselines.covariance import det_optimal
    from baselines.sparse import exhaustive

    task = tasks.get(name)
    kw = task.env_kwargs
    env = task.make_env()
    if task.family == "sparse":
        policy = exhaustive(kw["scenario"], kw["budget"], kw["horizon"], kw["objective"]).policy()
    else:
        policy = det_optimal(kw["scenario"], kw["power"]).policy(env.unwrapped.parallel)
    result = evaluate(policy, env, n_episodes=2, reference=1.0)
    env.close()
    # the stored optimum and the env's return are both this EXS plan's Φ, each computed with the
    # machine's BLAS: equal to the last few ulps on any CPU (bit for bit on the one that stored it)
    assert task.normalise(result.mean) == pytest.approx(1.0, abs=1e-12)
    assert result.mean == pytest.approx(task.references.optimum.value, rel=1e-14)
    heuristic = task.references.heuristic_score
    assert heuristic is not None and heuristic <= 0.9  # the greedy answer is far below it


@pytest.mark.parametrize(
    "name", ["detection-game/ch3-static-attacker-v0", "detection-game/ch3-tracking-attacker-v0"]
)
def test_the_detection_attacker_bound_holds_for_every_attack(name):
    from baselines.detection.response import DetectionGame

    task = tasks.get(name)
    refs = task.references
    best = refs.optimum
    assert not best.certified and 0.0 < best.gap <= GAP_HARD
    assert best.value <= best.bound and best.gap == pytest.approx(1 - best.value / best.bound)
    with task.make_env() as env:
        game = DetectionGame.of(env)
    # the bound is the no-detection maximum: the c2-maximising attack against a blind detector
    blind = game.threshold_action(math.inf)
    assert game.reward(game.attack_action(1.0, game.preset_sigma), blind) == pytest.approx(
        best.bound, rel=1e-9
    )
    # no attack the view can play earns more against its fixed detector (action 0)
    rng = np.random.default_rng(1)
    actions = rng.uniform(-1.0, 1.0, size=(40, 1 + game.cov_map.size))
    actions[:20, 0] = 1.0  # always attack
    rewards = [game.reward(a, np.zeros(1)) for a in actions]
    assert max(rewards) <= best.bound
    assert max(rewards) <= best.value  # the searched best response beats every sampled attack
    for value in refs.heuristics.values():
        assert refs.random.mean < value <= best.value


def test_the_dynamic_stealth_bound_holds_for_every_bias_attack():
    task = tasks.get("stealth/ch4-position-dynamic-bias-v0")
    best = task.references.optimum
    assert not best.certified and 0.0 < best.gap <= GAP_HARD
    assert best.value <= best.bound
    kwargs = dict(task.env_kwargs)
    venv = gym.make_vec(task.env_id, num_envs=64, vectorization_mode="vector_entry_point", **kwargs)
    rng = np.random.default_rng(3)
    try:
        venv.reset(seed=0)
        total = np.zeros(64)
        signs = rng.choice([-1.0, 1.0], size=(64, 3))
        for _ in range(kwargs["horizon"]):
            actions = rng.uniform(-1.0, 1.0, size=(64, 3))
            actions[:32] = signs[:32]  # half keep a constant sign pattern at full strength
            actions[32:48] = np.where(rng.random((16, 3)) < 0.8, signs[32:48], -signs[32:48])
            _, reward, _, _, infos = venv.step(actions.astype(np.float32))
            # a bias never lowers the detection probability below the false-alarm rate
            assert np.all(infos["detection_probability"] >= infos["alpha"] - 1e-12)
            total += reward
    finally:
        venv.close()
    assert total.max() <= best.bound
    assert total.max() <= best.value + 1e-12  # no sampled attack beats the best constant sign
    assert task.references.random.mean < best.value


PROTECT = "stealth/ch4-position-dynamic-protect-defender-v0"


def test_the_rotating_attacker_biases_one_sensor_per_step_in_turn():
    from fdia_env.tasks.catalog import rotating_bias

    policy = rotating_bias(3, 6)
    steps_left = np.array([[1 - k / 6, 0, 0, 0] for k in range(6)], dtype=np.float32)
    actions = policy.predict(steps_left)[0]
    assert np.array_equal(np.argmax(actions, axis=1), [0, 1, 2, 0, 1, 2])
    assert np.array_equal(actions.sum(axis=1), np.ones(6))


def test_the_protecting_defender_optimum_is_played_and_no_sampled_sequence_beats_it():
    from agents.bench.references import protection_returns, protection_schedule
    from agents.bench.score import score_policy

    task, spec = tasks.get(PROTECT), tasks.spec(PROTECT)
    refs = task.references
    assert (task.family, task.player, refs.objective) == ("stealth", "defender", "cost")
    assert refs.optimum.certified and refs.optimum.name.endswith("4^6 protection sequences")
    # the enumeration's best sequence: skip the protection at step 2 (sensor 2 attacked), so
    # the bias there raises the detector's statistic and an alarm stops the attacker's payoff
    best = score_policy(task, protection_schedule((1, 2, 0, 1, 2, 3), 3), (0,), episodes=1)
    assert best.mean == pytest.approx(refs.optimum.value, rel=1e-12)
    assert best.normalised == pytest.approx(1.0, abs=1e-9)
    rng = np.random.default_rng(0)
    sampled = [tuple(int(c) for c in rng.integers(0, 4, 6)) for _ in range(60)]
    fixed = [(c,) * 6 for c in range(4)]
    track = (1, 2, 3, 1, 2, 3)  # protect the sensor attacked at each step
    returns = protection_returns(spec, [*sampled, *fixed, track])
    assert returns.max() <= refs.optimum.value + 1e-12
    assert returns[60:64].max() == pytest.approx(refs.heuristics["best fixed protection"], 1e-12)
    assert returns[64] == pytest.approx(refs.heuristics["greedy protection"], rel=1e-12)
    assert refs.random.mean < returns[60:64].max() < returns[64] < refs.optimum.value


def test_the_catalogue_has_24_tasks_8_hard_and_both_players_of_every_family_with_two():
    from fdia_env.tasks.task import FAMILIES

    assert len(ALL) >= 24
    assert len(tasks.names(difficulty="hard")) >= 8
    played = {(t.family, t.player) for t in tasks.TASKS.values()}
    assert {family for family, _ in played} == set(FAMILIES)
    for family in ("sensor-game", "detection-game", "incomplete-information", "stealth"):
        assert {(family, "attacker"), (family, "defender")} <= played, family


def test_the_branch_and_bound_policy_played_in_the_env_scores_one_exactly():
    from baselines.sparse import branch_and_bound

    task = tasks.get("sparse/ch4-random-v0")  # C(18, 10) sets: its reference is B&B's
    assert task.references.optimum.name == "B&B (certified optimum)"
    kw = task.env_kwargs
    best = branch_and_bound(kw["scenario"], kw["budget"], kw["horizon"], kw["objective"])
    assert best.proved_optimal
    with task.make_env() as env:
        result = evaluate(best.policy(), env, n_episodes=2, reference=1.0)
    # the stored optimum and the env's return are both this EXS plan's Φ, each computed with the
    # machine's BLAS: equal to the last few ulps on any CPU (bit for bit on the one that stored it)
    assert task.normalise(result.mean) == pytest.approx(1.0, abs=1e-12)
    assert result.mean == pytest.approx(task.references.optimum.value, rel=1e-14)


def test_the_leaderboard_rows_cover_every_task_and_learner_with_three_seeds():
    """``results/bench/rows.json``: 3 seeds at one budget for each learner that fits a task."""
    import json
    from collections import defaultdict
    from pathlib import Path

    from experiments.bench.run import LEARNERS, applicable

    path = Path(__file__).resolve().parents[1] / "results" / "bench" / "rows.json"
    rows = json.loads(path.read_text(encoding="utf-8"))["rows"]
    assert {r["timesteps"] for r in rows} == {2048}
    seeds = defaultdict(set)
    for r in rows:
        seeds[r["task"], r["method"]].add(r["seed"])
    missing = [
        (name, algo, sorted(seeds[name, algo]))
        for name in ALL
        for algo in LEARNERS
        if applicable(tasks.get(name), algo) and seeds[name, algo] != {0, 1, 2}
    ]
    assert missing == []
    assert {name for name, _ in seeds} == set(ALL)  # every task has learner rows
    page = (path.parents[2] / "docs" / "benchmark.md").read_text(encoding="utf-8")
    board = page.split("<!-- leaderboard:start -->", 1)[1]
    assert f"({len(rows)} learner runs," in board  # rendered from these rows
    for name in ALL:  # each task's table: random, heuristics, reference, learners
        table = board.split(f"**{name}**", 1)[1].split("\n\n", 2)[1]
        refs = tasks.get(name).references
        for label in ["random", *refs.heuristics, refs.optimum.name]:
            assert f"| {label} |" in table, (name, label)
        for algo in {algo for task, algo in seeds if task == name}:
            assert f"| {algo} |" in table and "3 seeds, 2,048 steps" in table, (name, algo)


def test_a_pinned_older_version_builds_without_the_out_of_date_notice(monkeypatch):
    import warnings

    import gymnasium

    task = tasks.get("sparse/ch4-position-v0")
    assert task.env_id == "fdia_env/SparseAttack-v0"  # pinned: v2 is newer
    with warnings.catch_warnings(record=True) as direct:
        warnings.simplefilter("always")
        gymnasium.make(task.env_id, **task.env_kwargs).close()
    assert any("is out of date" in str(w.message) for w in direct)
    make = gymnasium.make

    def make_and_warn(*args, **kwargs):  # another deprecation while the env is built
        warnings.warn("some other notice", DeprecationWarning, stacklevel=2)
        return make(*args, **kwargs)

    with warnings.catch_warnings(record=True) as pinned:
        warnings.simplefilter("always")
        task.make_env().close()
        monkeypatch.setattr(gymnasium, "make", make_and_warn)
        task.make_env().close()
    assert not any("is out of date" in str(w.message) for w in pinned)
    assert [str(w.message) for w in pinned if w.category is DeprecationWarning] == [
        "some other notice"
    ]
