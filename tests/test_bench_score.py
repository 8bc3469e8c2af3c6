"""``python -m agents.bench score``: every kind of agent input, the leaderboard, the errors."""

import json
import shutil
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from agents.bench.agents import load_agent
from agents.bench.score import main, score, score_policy
from agents.checkpoint import UntrustedCheckpointError
from agents.evaluate import evaluate
from fdia_env.tasks import get

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # train.py lives at the root
TASK = "sparse/ch4-position-v0"  # train.py's default attacker settings: budget 5, horizon 6
TINY = ["--no-progress-bar", "--final-eval-episodes", "2", "--eval-freq", "0"]


@pytest.fixture(scope="module")
def task():
    return get(TASK)


@pytest.fixture(scope="module")
def sb3_run(tmp_path_factory):
    """A finished 128-step MaskablePPO train.py run on the task's settings."""
    import train

    root = tmp_path_factory.mktemp("runs")
    result = train.main(
        ["attacker", "--total-timesteps", "128", "--n-steps", "64", "--batch-size", "32",
         "--n-epochs", "1", *TINY, "--runs-root", str(root)]
    )  # fmt: skip
    return result.run_dir


def direct_mean(policy, task, seed=0, episodes=None):
    with task.make_env() as env:
        return evaluate(policy, env, episodes or task.episodes, seed=seed).mean


def test_random_play_on_the_reference_episodes_scores_zero(task):
    rand = task.references.random
    if rand.episodes == 0:
        pytest.skip("this task's random reference is exact, not played")
    result = score(task, "random", seeds=(rand.seed // 100_000,), episodes=rand.episodes)
    if rand.seed % 100_000:
        pytest.skip("the stored random reference is played from another first seed")
    assert result.mean == pytest.approx(rand.mean, rel=1e-12)
    assert abs(result.normalised) < 1e-9


def test_the_optimal_plan_as_a_callable_scores_one_exactly(task, tmp_path, monkeypatch):
    module = tmp_path / "my_exs_agent.py"
    module.write_text(
        textwrap.dedent(
            """
            from baselines.sparse import exhaustive

            PLAN = exhaustive("ch4-position", budget=5, horizon=6).policy()


            def act(observation, action_masks=None):
                return PLAN.predict(observation)[0]
            """
        )
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    for agent in ("my_exs_agent:act", "my_exs_agent:PLAN"):
        result = score(task, agent, seeds=(0, 1), episodes=2)
        assert result.returns.shape == (2, 2)
        assert result.mean == pytest.approx(task.references.optimum.value, rel=1e-12)
        assert result.normalised == pytest.approx(1.0, abs=1e-12)
        assert result.per_seed == pytest.approx((1.0, 1.0), abs=1e-12)


def test_an_sb3_run_folder_scores_as_its_model_plays(task, sb3_run):
    result = score(task, sb3_run, seeds=(0,), episodes=3)
    from agents.bench.agents import load_agent as load

    with task.make_env() as env:
        model = load(sb3_run, task, env).policy
    assert result.description.startswith("stable-baselines3 MaskablePPO, 128 steps")
    assert result.mean == pytest.approx(direct_mean(model, task, episodes=3), rel=1e-12)
    assert result.normalised == pytest.approx(task.normalise(result.mean), rel=1e-12)
    # the model file alone (its run's config.json beside it is checked too)
    alone = score(task, sb3_run / "model.json", seeds=(0,), episodes=3)
    assert alone.mean == pytest.approx(result.mean, rel=1e-12)


def test_an_sb3_zip_needs_trust_and_its_algorithm(task, sb3_run, tmp_path):
    from stable_baselines3.common.vec_env import DummyVecEnv

    from agents.checkpoint import load_model

    with task.make_env() as env:
        model = load_model(sb3_run / "model.json", DummyVecEnv([lambda: env]), sb3_run)
    zip_path = tmp_path / "agent.zip"
    model.save(zip_path)
    with pytest.raises(UntrustedCheckpointError, match="trust_checkpoint"):
        score(task, zip_path)
    with pytest.raises(ValueError, match="algo is needed"):
        score(task, zip_path, trust_checkpoint=True)
    result = score(task, zip_path, seeds=(0,), episodes=3, algo="MaskablePPO",
                   trust_checkpoint=True)  # fmt: skip
    assert result.mean == pytest.approx(direct_mean(model, task, episodes=3), rel=1e-12)
    code = main(["--task", TASK, "--agent", str(zip_path), "--algo", "MaskablePPO"])
    assert code == 2


def test_a_torch_ppo_policy_file_scores_as_it_plays(task, tmp_path):
    import torch

    from agents.torch_ppo import ActorCritic, PolicySpec, TorchPolicy, save_policy

    torch.manual_seed(0)
    with task.make_env() as env:
        policy = TorchPolicy(ActorCritic(PolicySpec.of(env.observation_space, env.action_space)))
    path = save_policy(policy, tmp_path / "policy.json", num_timesteps=7)
    result = score(task, path, seeds=(0,), episodes=3)
    assert result.description == "torch-ppo, 7 steps"
    assert result.mean == pytest.approx(direct_mean(policy, task, episodes=3), rel=1e-12)


def test_a_checkpoint_of_another_task_is_refused_naming_the_agent(task, sb3_run, tmp_path):
    other = tmp_path / "other"
    shutil.copytree(sb3_run, other)
    (other / ".lock").unlink(missing_ok=True)
    config = json.loads((other / "config.json").read_text())
    config["resolved"]["env_kwargs"]["budget"] = 4
    (other / "config.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match=r"agent .*other env options.*budget=4 \(task: 5\)"):
        score(task, other)
    with pytest.raises(ValueError, match=r"agent .*budget=4"):
        score(task, other / "model.json")
    config["resolved"]["gym_id"] = "fdia_env/CovarianceAttack-v0"
    (other / "config.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match="trained on fdia_env/CovarianceAttack-v0"):
        score(task, other)


def test_a_policy_of_other_spaces_is_refused(task, tmp_path):
    from gymnasium import spaces

    from agents.torch_ppo import ActorCritic, PolicySpec, TorchPolicy, save_policy

    wrong = PolicySpec.of(spaces.Box(-1, 1, (3,)), spaces.Discrete(4))
    path = save_policy(TorchPolicy(ActorCritic(wrong)), tmp_path / "p.json")
    with pytest.raises(ValueError, match=r"agent .* trained on another task"):
        score(task, path)


def test_bad_task_agent_and_seeds_are_clear_errors(task, capsys):
    with pytest.raises(ValueError, match="task"):
        score("sparse/no-such-task-v0", "random")
    with pytest.raises(ValueError, match="agent 'nowhere/at/all' is neither"):
        score(task, "nowhere/at/all")
    with pytest.raises(ValueError, match="cannot import module 'no_such_module_x'"):
        score(task, "no_such_module_x:act")
    with pytest.raises(ValueError, match="seeds must be"):
        score(task, "random", seeds=())
    with pytest.raises(ValueError, match="episodes must be"):
        score(task, "random", episodes=0)
    assert main(["--task", "sparse/no-such-task-v0", "--agent", "random"]) == 2
    assert "task" in capsys.readouterr().err


def test_the_command_prints_raw_normalised_and_references(task, capsys, tmp_path):
    out_json = tmp_path / "score.json"
    code = main(["--task", TASK, "--agent", "random", "--seeds", "2", "--episodes", "3",
                 "--json", str(out_json)])  # fmt: skip
    assert code == 0
    text = capsys.readouterr().out
    data = json.loads(out_json.read_text())
    assert data["seeds"] == [0, 1] and data["episodes"] == 3
    assert f"normalised  {data['normalised']:.4f}" in text
    assert "raw return" in text and "per seed" in text
    best = task.references.optimum
    assert best.name in text and "1.0000" in text  # the optimum beside the score
    assert "random" in text.split("references", 1)[1]
    assert data["normalised_ci"][0] <= data["normalised"] <= data["normalised_ci"][1]


def test_a_game_task_is_scored_by_exploitability():
    from fdia_env.tasks import names

    games = [n for n in names() if get(n).is_game]
    if not games:
        pytest.skip("no game task")
    game = get(games[0])
    with game.make_env() as env:
        from agents.registry import by_gym_id

        ref = by_gym_id(game.env_id).reference_of(env)
    result = score_policy(game, ref.policy, seeds=(0,), episodes=game.episodes)
    assert result.raw_name == "worst-case return"
    assert result.extras["exploitability"] == pytest.approx(0.0, abs=1e-6)
    assert result.normalised == pytest.approx(1.0, abs=1e-6)
    uniform = score_policy(game, "random", seeds=(0,), episodes=game.episodes)
    # the stored random reference is the uniform mix's exact worst-case return
    assert uniform.raw == pytest.approx(game.references.random.mean, rel=1e-9)
    assert uniform.normalised == pytest.approx(0.0, abs=1e-9)


def test_learned_rows_render_as_mean_and_ci_over_seeds(task, tmp_path):
    from experiments.bench.render import END, START, leaderboard, write_section

    rows = [
        {"task": TASK, "method": "PPO", "seed": s, "normalised": v, "mean": m, "timesteps": 100,
         "train_seconds": 1.0}
        for s, v, m in ((0, 0.5, 1.0), (1, 0.7, 2.0), (2, 0.6, 3.0))
    ]  # fmt: skip
    text = leaderboard([task], rows, tmp_path, "header")
    # mean 0.6, 95 % t interval 4.303 * 0.1 / sqrt(3) = 0.248
    assert "| PPO | 0.600 ± 0.248 | 2 | 3 seeds, 100 steps, 1 s per seed |" in text
    assert f"| {task.references.optimum.name} | 1.000 |" in text
    assert "| random | 0.000 |" in text
    assert (tmp_path / "benchmark_sparse.png").stat().st_size > 1000
    page = tmp_path / "board.txt"
    page.write_text(f"# B\n\n{START}\nold\n{END}\n\ntail\n")
    write_section(page, "new")
    assert page.read_text() == f"# B\n\n{START}\n\nnew\n\n{END}\n\ntail\n"
    page.write_text("# no markers\n")
    with pytest.raises(ValueError, match="markers"):
        write_section(page, "new")


def test_load_agent_gives_the_random_policy(task):
    with task.make_env() as env:
        loaded = load_agent("random", task, env)
    assert loaded.policy == "random" and loaded.kind == "random"


def test_an_rllib_run_state_scores_as_its_module_plays(task, tmp_path):
    pytest.importorskip("ray.rllib")
    import torch

    from agents.checkpoint import save_pair
    from agents.rllib.config import ppo_config
    from agents.rllib.envs import make_view
    from agents.rllib.policy import RLlibPolicy
    from agents.rllib.state import FORMAT, STATE, TENSORS

    kwargs = dict(task.env_kwargs)
    config = ppo_config(task.env_id, kwargs, total_timesteps=1)
    with make_view(task.env_id, kwargs) as view:
        module = config.get_rl_module_spec(env=view, inference_only=False).build()
    torch.manual_seed(1)
    with torch.no_grad():  # weights of its own, so the scores below depend on them
        for p in module.parameters():
            p.normal_()
    run = tmp_path / "rllib-run"
    run.mkdir()
    (run / "config.json").write_text(json.dumps({
        "command": "attacker",
        "resolved": {"backend": "rllib", "env": task.env_id, "algo": "PPO", "env_kwargs": kwargs,
                     "hyperparameters": {"net_arch": [64, 64]}},
    }))  # fmt: skip
    weights = {k: v.detach().clone() for k, v in module.state_dict().items()}
    meta = {"format": FORMAT, "iteration": 1, "modules": ["default_policy"], "optimizers": {},
            "timesteps": 200}  # fmt: skip
    save_pair(run / STATE, run / TENSORS, {"state_dicts": {"rl_module/default_policy": weights},
                                           "variables": {}}, meta)  # fmt: skip
    result = score(task, run, seeds=(0,), episodes=3)
    assert result.description == "RLlib PPO, 200 steps"
    with task.make_env() as env:
        direct = RLlibPolicy(module.eval(), env.action_space, masked=True)
    assert result.mean == pytest.approx(direct_mean(direct, task, episodes=3), rel=1e-12)
    alone = score(task, run / STATE, seeds=(0,), episodes=3)
    assert alone.mean == result.mean


def test_an_sb3_model_in_a_game_is_scored_on_its_action_distribution():
    from stable_baselines3.common.vec_env import DummyVecEnv

    from agents.algos import build_model
    from agents.config import Hyperparameters, algo_kwargs

    game = get("sensor-game/ch5-game-attacker-v0")
    with game.make_env() as env:
        model = build_model(
            "PPO", DummyVecEnv([lambda: env]), algo_kwargs("PPO", Hyperparameters()), 3
        )
        import torch

        obs, _ = env.reset(seed=0)
        obs_t, _ = model.policy.obs_to_tensor(obs)
        with torch.no_grad():
            probs = model.policy.get_distribution(obs_t).distribution.probs.numpy().ravel()
    # float32 probabilities: their sum misses 1 by more than the game solver's 1e-9 tolerance
    assert abs(probs.astype(np.float64).sum() - 1.0) > 1e-9
    result = score_policy(game, model, seeds=(0,), episodes=2)
    # an untrained network plays close to the uniform mix: close to random play's score, 0
    assert result.description == "" and abs(result.normalised) < 0.5
    assert result.extras["exploitability"] > 0


def test_a_game_with_a_subset_size_limit_scores_its_equilibrium_one_and_random_zero():
    from agents.registry import by_gym_id

    game = get("sensor-game/m10-strong-k3-defender-v0")  # defender subsets of at most 3 sensors
    with game.make_env() as env:
        ref = by_gym_id(game.env_id).reference_of(env)
        n = env.action_space.n
    assert ref.payoff.shape[0] == n == 176  # the game matrix has the env actions only
    expl = score_policy(game, ref.policy, seeds=(0,), episodes=2)
    assert expl.normalised == pytest.approx(1.0, abs=1e-9)
    rand = score_policy(game, "random", seeds=(0,), episodes=2)
    assert rand.normalised == pytest.approx(0.0, abs=1e-9)


def test_torch_ppo_makes_several_updates_on_a_short_budget():
    from agents.torch_ppo import TorchPPOConfig
    from experiments.bench.run import TORCH_MIN_ITERATIONS, torch_envs

    for budget, members in ((2048, 21), (20_000, 208), (1_000_000, 256), (10, 1)):
        assert torch_envs(budget) == members
        config = TorchPPOConfig(total_timesteps=budget, num_envs=members)
        if budget >= 96:  # a budget of at least one rollout of 8 members
            assert config.iterations >= TORCH_MIN_ITERATIONS


def test_torch_ppo_is_offered_only_where_the_env_runs_on_torch(monkeypatch):
    import fdia_env.registration as registration
    from experiments.bench.run import applicable

    assert applicable(get(TASK), "torch-ppo")
    assert not applicable(get("system-family/tracking-m6-v0"), "torch-ppo")  # no vector env
    assert applicable(get("system-family/tracking-m6-v0"), "PPO")
    typed = get("incomplete-information/ch5-game-informed-attacker-v0")  # typed: torch too
    assert typed.env_id in registration.torch_ids() and applicable(typed, "torch-ppo")
    numpy_only = tuple(i for i in registration.torch_ids() if i != get(TASK).env_id)
    monkeypatch.setattr(registration, "torch_ids", lambda: numpy_only)
    assert not applicable(get(TASK), "torch-ppo")  # its env without a torch backend
    assert applicable(get(TASK), "PPO")


def test_sac_and_dqn_are_offered_only_for_their_kind_of_action_space():
    """Regression: SAC was offered on a stealth task whose actions are MultiBinary."""
    from experiments.bench.run import applicable

    assert not applicable(get("stealth/ieee14-b3-v0"), "SAC")  # MultiBinary(13) actions
    assert applicable(get("stealth/ch4-position-dynamic-bias-v0"), "SAC")  # Box actions
    assert not applicable(get("stealth/ch4-position-dynamic-bias-v0"), "DQN")


def test_torch_ppo_is_not_offered_on_a_sensor_game_over_more_than_62_sensors():
    """Regression: the torch env failed at reset with a KeyError on IEEE 118's 304 meters."""
    import dataclasses

    from agents.torch_ppo import make_torch_env
    from experiments.bench.run import applicable
    from fdia_env.systems.tracking import tracking_system

    game = get("sensor-game/ch5-game-attacker-v0")
    for sensors, fits in ((62, True), (63, False)):
        system = tracking_system(0.5, list(np.linspace(1.0, 3.0, sensors)))
        kwargs = {"scenario": system, "power": 10.0, "max_subset_size": 1}
        assert applicable(dataclasses.replace(game, env_kwargs=kwargs), "torch-ppo") is fits
    env = make_torch_env(game.env_id, 2, "cpu", **kwargs)
    with pytest.raises(ValueError, match=r"backend='torch' .* at most 62 sensors, got M = 63"):
        env.reset(seed=0)
    env.close()


def test_the_tutorial_scores_a_policy_in_under_20_lines_of_code():
    """Lines holding code in docs/tutorials/score_policy.py (no comments, docstrings, blanks)."""
    import ast
    import io
    import tokenize

    source = (ROOT / "docs" / "tutorials" / "score_policy.py").read_text(encoding="utf-8")
    docstrings = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef)):
            if ast.get_docstring(node) is not None:
                first = node.body[0]
                docstrings |= set(range(first.lineno, first.end_lineno + 1))
    skip = {tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT}
    code = set()
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type not in skip | {tokenize.ENDMARKER}:
            code |= set(range(token.start[0], token.end[0] + 1))
    assert 10 <= len(code - docstrings) < 20
    assert "score_policy(task, LastSteps()" in source  # the user's own policy is what it scores


def test_a_run_of_another_sparse_version_is_accepted_only_where_the_env_is_the_same():
    from types import SimpleNamespace

    from agents.bench.agents import check_trained_on

    grid = {"scenario": "grid-ieee14", "budget": 2, "horizon": 1}
    pinned = SimpleNamespace(  # a task pinned to v0 above 16 sensors: MultiBinary(34)
        name="sparse/grid-v0", env_id="fdia_env/SparseAttack-v0", env_kwargs=grid,
        module="fdia_env.sparse_attack_v0",
    )  # fmt: skip
    # v2's default there is the sequential format's plan-first order: another env
    with pytest.raises(ValueError, match="trained on fdia_env/SparseAttack-v2, but task"):
        check_trained_on("run", "fdia_env/SparseAttack-v2", grid, pinned)
    check_trained_on("run", "fdia_env/SparseAttack-v2", {**grid, "action": "multibinary"}, pinned)
    plan = SimpleNamespace(**{**vars(pinned), "env_kwargs": {**grid, "action": "sequential"}})
    with pytest.raises(ValueError, match="trained on fdia_env/SparseAttack-v2"):  # v0: "time"
        check_trained_on("run", "fdia_env/SparseAttack-v2", grid, plan)
    plan.env_kwargs["order"] = "plan"
    check_trained_on("run", "fdia_env/SparseAttack-v2", grid, plan)
    # another env altogether stays refused
    with pytest.raises(ValueError, match="trained on fdia_env/CovarianceAttack-v0"):
        check_trained_on("run", "fdia_env/CovarianceAttack-v0", {}, pinned)


# ------------------------------------------------------------------------------ actions


def _plan():
    from baselines.sparse import exhaustive

    return exhaustive("ch4-position", budget=5, horizon=6).policy()


@pytest.mark.parametrize(
    "bad", [1.5, "3", None, [3], np.array([3]), float("inf"), float("nan"), 3.0, np.float64(3.0)]
)
def test_an_action_outside_the_space_is_refused_naming_the_agent(task, bad):
    from agents.bench.agents import CallablePolicy
    from agents.evaluate import InvalidActionError

    policy = CallablePolicy(lambda obs: bad, "mine")
    with pytest.raises(InvalidActionError) as info:
        score_policy(task, policy, seeds=(0,), episodes=1, agent="my_agent:act")
    text = str(info.value)
    assert text.startswith("agent my_agent:act: policy CallablePolicy returned an action")
    assert "Discrete(8)" in text and "[0, 8)" in text  # the allowed actions
    assert repr(bad) in text


def test_integer_actions_of_any_integer_type_score_alike(task):
    from agents.bench.agents import CallablePolicy

    plan = _plan()
    means = []
    for kind in (int, np.int64, np.int32, np.asarray):
        policy = CallablePolicy(lambda obs, kind=kind: kind(int(plan.predict(obs)[0])), "k")
        means.append(score_policy(task, policy, seeds=(0,), episodes=2).mean)
    assert means == pytest.approx([task.references.optimum.value] * 4, rel=1e-12)


def test_the_command_reports_a_bad_action_as_an_error(task, tmp_path, monkeypatch, capsys):
    (tmp_path / "half_agent.py").write_text("def act(observation):\n    return 1.5\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    assert main(["--task", TASK, "--agent", "half_agent:act", "--seeds", "1"]) == 2
    err = capsys.readouterr().err
    assert "agent half_agent:act: policy CallablePolicy returned an action outside" in err
    assert "got 1.5" in err


# ------------------------------------------------------------------------------ run configs


def _drop(key):
    def edit(resolved):
        resolved.pop(key)

    return edit


def _null_option(key):
    def edit(resolved):
        resolved["env_kwargs"][key] = None

    return edit


def _drop_option(key):
    def edit(resolved):
        resolved["env_kwargs"].pop(key)

    return edit


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ("no resolved", r"config\.json has no 'resolved' object \(got None\)"),
        ("null resolved", r"config\.json has no 'resolved' object \(got None\)"),
        (_drop("gym_id"), r"config\.json: resolved\.gym_id is None, not an env id"),
        (lambda r: r.update(gym_id=None), r"config\.json: resolved\.gym_id is None"),
        (lambda r: r.update(gym_id=""), r"config\.json: resolved\.gym_id is '', not an env id"),
        (_drop("env_kwargs"), r"config\.json: resolved\.env_kwargs is None, not an object"),
        (lambda r: r.update(env_kwargs=[]), r"config\.json: resolved\.env_kwargs is \[\]"),
        (_null_option("budget"), r"config\.json: resolved\.env_kwargs\.budget is null"),
        (_null_option("horizon"), r"config\.json: resolved\.env_kwargs\.horizon is null"),
        (
            _drop_option("budget"),
            r"config\.json records no value for resolved\.env_kwargs\.budget \(task "
            r"sparse/ch4-position-v0 plays budget=5\)",
        ),
    ],
    ids=[
        "no-resolved", "null-resolved", "no-gym_id", "null-gym_id", "empty-gym_id",
        "no-env_kwargs", "list-env_kwargs", "null-budget", "null-horizon", "no-budget",
    ],
)  # fmt: skip
def test_a_run_whose_training_options_cannot_be_established_is_refused(
    task, sb3_run, tmp_path, edit, message
):
    run = tmp_path / "run"
    shutil.copytree(sb3_run, run)
    (run / ".lock").unlink(missing_ok=True)
    config = json.loads((run / "config.json").read_text())
    if edit == "no resolved":
        del config["resolved"]
    elif edit == "null resolved":
        config["resolved"] = None
    else:
        edit(config["resolved"])
    (run / "config.json").write_text(json.dumps(config))
    for agent in (run, run / "model.json"):
        with pytest.raises(ValueError, match=message) as info:
            score(task, agent, seeds=(0,), episodes=1)
        assert str(info.value).startswith(f"agent {agent}: {run / 'config.json'}")


def test_a_run_of_another_budget_with_its_budget_nulled_is_refused(task, sb3_run, tmp_path):
    """A budget-3 run whose recorded budget is nulled is not scored on the budget-5 task."""
    run = tmp_path / "run"
    shutil.copytree(sb3_run, run)
    (run / ".lock").unlink(missing_ok=True)
    config = json.loads((run / "config.json").read_text())
    config["resolved"]["env_kwargs"]["budget"] = 3
    (run / "config.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match=r"budget=3 \(task: 5\)"):
        score(task, run, seeds=(0,), episodes=1)
    config["resolved"]["env_kwargs"]["budget"] = None
    (run / "config.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match=r"resolved\.env_kwargs\.budget is null"):
        score(task, run, seeds=(0,), episodes=1)


# ------------------------------------------------------------------------------ output paths


def _read_only_folder(tmp_path):
    """A folder no file can be created in (a read-only mode, or a read-only file system)."""
    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        (folder / "probe").write_text("x")
    except OSError:
        return folder
    (folder / "probe").unlink()  # root ignores the mode: a read-only file system then
    for candidate in (Path("/sys"), Path("/proc/sys/kernel")):
        try:
            with open(candidate / "fdia_env_probe.json", "a"):
                pass
        except OSError:
            return candidate
    pytest.skip("no read-only location on this machine")


def _read_only_file(tmp_path):
    """An existing file that cannot be opened for writing."""
    page = tmp_path / "page.txt"
    page.write_text("x")
    page.chmod(0o444)
    try:
        with open(page, "r+"):
            pass
    except OSError:
        return page
    candidate = Path("/proc/sys/kernel/ostype")
    try:
        with open(candidate, "r+"):
            pass
    except OSError:
        return candidate
    pytest.skip("no read-only file on this machine")


def test_score_json_to_a_folder_a_file_parent_or_a_read_only_place_is_refused_first(
    tmp_path, capsys
):
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    cases = [
        (tmp_path, f"--json {tmp_path}: is a folder; give a file path"),
        (a_file / "score.json", f"its parent {a_file} is not a folder"),
        (_read_only_folder(tmp_path) / "score.json", "cannot"),
    ]  # fmt: skip
    for path, message in cases:
        argv = ["--task", TASK, "--agent", "random", "--seeds", "1", "--episodes", "1"]
        assert main([*argv, "--json", str(path)]) == 2
        out, err = capsys.readouterr()
        assert message in err and err.startswith(f"error: --json {path}")
        assert "normalised" not in out  # refused before scoring


def test_score_json_creates_its_missing_folders(tmp_path, capsys):
    path = tmp_path / "new" / "deeper" / "score.json"
    argv = ["--task", TASK, "--agent", "random", "--seeds", "1", "--episodes", "1"]
    assert main([*argv, "--json", str(path)]) == 0
    assert json.loads(path.read_text())["task"] == TASK


def test_table_page_a_folder_a_missing_file_or_a_read_only_one_is_a_clear_error(tmp_path, capsys):
    from agents.bench.__main__ import main as bench

    read_only = _read_only_file(tmp_path)
    for page, message in (
        (tmp_path, "is a folder"),
        (tmp_path / "missing" / "page.txt", "does not exist"),
        (read_only, "cannot be read and written"),
    ):
        assert bench(["table", "--page", str(page)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"error: --page {page}: {message}")


def test_a_task_whose_optimum_is_only_bounded_says_what_1_is():
    # the dynamic stealth task's reference is the best of 8 constant-sign biases, bounded above
    # by 0.1801988903 (raw): its score's 1 is that best known value, never "1 = optimum"
    from agents.bench.score import Score, report

    task = get("stealth/ch4-position-dynamic-bias-v0")
    best = task.references.optimum
    assert not best.certified
    result = Score(
        task.name,
        "x",
        "",
        (0,),
        np.full((1, 2), best.value),
        best.value,
        0.0,
        1.0,
        (1.0, 1.0),
        (1.0,),
    )
    text = report(result, task)
    bound = (best.bound - task.references.random.mean) / (best.value - task.references.random.mean)
    assert f"1 = best known ({best.name}); the optimum is at most {bound:.4f})" in text
    assert "1 = optimum" not in text and f"{bound:.4f}" == "1.1232"
    certified = get(TASK)
    assert "(0 = random, 1 = optimum)" in report(result, certified)
