"""The leaderboard runner (``fdia-leaderboard``, ``python -m experiments bench``).

It writes only under the paths it is given (checked before any training), its ``--hp`` reaches
every learner (torch-ppo's members and rollout included) and is checked against each learner's
hyperparameters, a rerun resumes, and a failed run is a failed row while the others go on.
"""

import json
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

from experiments.cli import main as experiments

ROOT = Path(__file__).resolve().parent.parent
TASK = "sparse/ch4-position-v0"  # budget 5 of 8 sensors, horizon 6: a tiny run trains in seconds
SKIP = {".git", ".venv", "__pycache__", ".pytest_cache", ".ruff_cache", ".hypothesis"}


def listing(folder: Path) -> dict[str, tuple[int, int]]:
    """Every file under ``folder`` (caches and the venv left out): its size and mtime."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(folder):
        dirnames[:] = [d for d in dirnames if d not in SKIP]
        for name in filenames:
            path = Path(dirpath, name)
            stat = path.lstat()
            out[path.relative_to(folder).as_posix()] = (stat.st_size, stat.st_mtime_ns)
    return out


def changed(before: dict, after: dict) -> set[str]:
    """The files added, removed or modified between two listings."""
    return {p for p in before.keys() | after.keys() if before.get(p) != after.get(p)}


def bench(*argv: str) -> int:
    return experiments(["bench", *argv])


def test_the_runner_writes_only_where_it_is_told(tmp_path, monkeypatch, capsys):
    """Regression: the page's missing folder stopped the run after training (and by default it
    rewrote the checkout's docs/benchmark.md)."""
    import agents.leaderboard.run as run

    cwd, tmp, out = tmp_path / "cwd", tmp_path / "tmp", tmp_path / "out"
    cwd.mkdir()
    tmp.mkdir()
    monkeypatch.chdir(cwd)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    checkout, before = listing(ROOT), listing(tmp_path)
    rows_file = out / "a" / "rows.json"
    tiny = ["--tasks", TASK, "--algo", "PPO", "--seeds", "1", "--timesteps", "64",
            "--episodes", "2", "--hp", "n_steps", "64", "--hp", "batch_size", "32",
            "--hp", "n_epochs", "1", "--out", str(rows_file)]  # fmt: skip
    assert bench(*tiny) == 0
    assert changed(before, listing(tmp_path)) == {
        "out/a/rows.json",
        "out/a/leaderboard.md",
        "out/a/figures/benchmark_sparse.png",
    }
    rows = json.loads(rows_file.read_text())["rows"]
    assert [(r["task"], r["method"], r["seed"], r["timesteps"], r["status"]) for r in rows] == [
        (TASK, "PPO", 0, 64, "ok")
    ]
    assert np.isfinite(rows[0]["normalised"]) and rows[0]["episodes"] == 2
    assert rows[0]["hyperparameters"] == {"n_steps": 64, "batch_size": 32, "n_epochs": 1}
    page = (out / "a" / "leaderboard.md").read_text()
    assert f"| PPO | {rows[0]['normalised']:.3f} |" in page
    assert "](figures/benchmark_sparse.png)" in page

    # the same --out again, the page and figures elsewhere: nothing trains, both are rendered
    calls = []
    monkeypatch.setattr(run, "learner_row", lambda *a, **k: calls.append(a))
    before = listing(tmp_path)
    page, figures = out / "b" / "c" / "page.md", out / "d" / "fig"
    assert bench(*tiny, "--page", str(page), "--figures", str(figures)) == 0
    assert calls == []
    assert changed(before, listing(tmp_path)) == {
        "out/b/c/page.md",
        "out/d/fig/benchmark_sparse.png",
    }
    assert "](../../d/fig/benchmark_sparse.png)" in page.read_text()
    assert "skipped  already in --out: normalised" in capsys.readouterr().out
    assert listing(ROOT) == checkout  # docs/benchmark.md and every other checkout file alike


def test_the_outputs_are_checked_before_any_training(tmp_path, monkeypatch, capsys):
    import agents.leaderboard.run as run

    def no_training(*args, **kwargs):
        raise AssertionError("trained before the outputs were checked")

    monkeypatch.setattr(run, "learner_row", no_training)
    rows = tmp_path / "rows.json"
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    plain = tmp_path / "plain.md"
    plain.write_text("# a page without the markers\n")
    cases = [
        (["--out", str(tmp_path)], f"--out {tmp_path}: is a folder"),
        (["--out", str(a_file / "rows.json")], f"--out {a_file / 'rows.json'}: its parent"),
        (["--out", str(rows), "--page", str(tmp_path)], f"--page {tmp_path}: is a folder"),
        (["--out", str(rows), "--page", str(plain)], f"--page {plain}: has no <!-- leaderboard"),
        (["--out", str(rows), "--page", str(a_file / "p.md")], f"--page {a_file / 'p.md'}: its"),
        (["--out", str(rows), "--page", str(rows)], f"--page {rows}: is the --out rows file"),
        (["--out", str(rows), "--figures", str(a_file)], f"--figures {a_file}: is a file"),
        (["--out", str(rows), "--figures", str(a_file / "f")], f"--figures {a_file / 'f'}: a"),
        ([], "the following arguments are required: --out"),
    ]
    if Path("/proc/self").is_dir():  # a folder that cannot be created, even by root
        cases.append((["--out", "/proc/fdia-none/rows.json"], "cannot create its folder"))
    for argv, needle in cases:
        with pytest.raises(SystemExit) as exc:
            bench("--tasks", TASK, "--algo", "PPO", "--seeds", "1", *argv)
        assert exc.value.code == 2
        assert needle in capsys.readouterr().err, argv
    assert plain.read_text() == "# a page without the markers\n"
    assert not rows.exists()


@pytest.mark.parametrize("content", ["not json\n", "[1, 2]\n", '{"rows": 3}\n'])
def test_the_runner_refuses_an_out_file_that_is_no_rows_file(tmp_path, capsys, content):
    out = tmp_path / "rows.json"
    out.write_text(content, encoding="utf-8")
    with pytest.raises(SystemExit) as exc:
        bench("--tasks", TASK, "--out", str(out), "--no-render")
    assert exc.value.code == 2
    assert f"--out {out}: not a rows file" in capsys.readouterr().err
    assert out.read_text(encoding="utf-8") == content


def test_bad_options_and_hyperparameters_are_refused_naming_the_option(tmp_path, capsys):
    torch_names = (
        "learning_rate, gamma, n_steps, n_epochs, ent_coef, gae_lambda, clip_range, "
        "lr_schedule, net_arch, stop_prob, norm_obs, num_envs"
    )
    for argv, needle in (
        (["--algo", "torch-ppo", "--hp", "n_stepz", "3"],
         f"--hp n_stepz: not a hyperparameter of torch-ppo; torch-ppo takes {torch_names}"),
        (["--algo", "PPO,DQN", "--hp", "n_steps", "64"],
         "--hp n_steps: not a hyperparameter of DQN; DQN takes learning_rate, gamma, batch_size"),
        (["--algo", "PPO", "--hp", "SAC:tau", "0.1"], "--hp SAC:tau: 'SAC' is not a learner"),
        (["--algo", "torch-ppo", "--hp", "num_envs", "0"],
         "--hp for torch-ppo: num_envs must be in [1, "),
        (["--algo", "PPO", "--hp", "n_steps", "1"], "--hp for PPO: n_steps (--n-steps) must be"),
        (["--algo", "Nope"], "--algo must name learners"),
        (["--tasks", "sparse/none-v0"], "tasks must be 'all'"),
    ):  # fmt: skip
        with pytest.raises(SystemExit):
            bench(*argv, "--out", str(tmp_path / "rows.json"), "--no-render")
        assert needle in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # refused before --out was touched


def test_hp_reaches_torch_ppo_members_and_rollout(tmp_path, monkeypatch):
    """Regression: torch-ppo ignored --hp and always used min(256, steps / 96) members."""
    import agents.torch_ppo as torch_ppo

    used = []
    real = torch_ppo.train_torch_ppo

    def spy(env, config, **kwargs):
        result = real(env, config, **kwargs)
        used.append((env.num_envs, config.num_steps, len(result.history), result.timesteps))
        return result

    monkeypatch.setattr(torch_ppo, "train_torch_ppo", spy)
    tiny = ["--tasks", TASK, "--algo", "torch-ppo", "--seeds", "1", "--timesteps", "256",
            "--episodes", "2", "--no-render"]  # fmt: skip
    out = tmp_path / "rows.json"
    assert bench(*tiny, "--out", str(out), "--hp", "num_envs", "4", "--hp", "n_steps", "8") == 0
    assert used == [(4, 8, 8, 256)]  # 8 updates of 4 members x 8 steps
    row = json.loads(out.read_text())["rows"][0]
    assert row["hyperparameters"] == {"num_envs": 4, "n_steps": 8}
    assert row["training"] == {"num_envs": 4, "num_steps": 8, "iterations": 8, "timesteps": 256}
    used.clear()  # the defaults: 256 // (12 x 8) = 2 members, 12 steps, ceil(256 / 24) updates
    assert bench(*tiny, "--out", str(tmp_path / "default.json")) == 0
    assert used == [(2, 12, 11, 264)]


def fake_learner(calls, fail=(), interrupt=()):
    """A ``learner_row`` that records its seeds, raising for those in ``fail``/``interrupt``."""

    def learner_row(task, algo, seed, timesteps, episodes=None, hp=None):
        calls.append(seed)
        if seed in fail:
            raise RuntimeError("boom")
        if seed in interrupt:
            raise KeyboardInterrupt
        return {"task": task.name, "method": algo, "seed": seed, "timesteps": timesteps,
                "status": "ok", "hyperparameters": dict(hp or {}), "normalised": 0.25,
                "raw": 1.0, "train_seconds": 0.1}  # fmt: skip

    return learner_row


def test_a_failed_run_is_a_failed_row_the_others_go_on_and_a_rerun_retries_it(
    tmp_path, monkeypatch, capsys
):
    import agents.leaderboard.run as run

    out, page = tmp_path / "rows.json", tmp_path / "page.md"
    calls: list[int] = []
    monkeypatch.setattr(run, "learner_row", fake_learner(calls, fail={1}))
    argv = ["--tasks", TASK, "--algo", "PPO", "--seeds", "3", "--timesteps", "64",
            "--out", str(out), "--page", str(page)]  # fmt: skip
    assert bench(*argv) == 1
    assert calls == [0, 1, 2]
    captured = capsys.readouterr()
    assert f"FAILED {TASK} PPO seed 1: RuntimeError: boom" in captured.err
    assert "1 run(s) failed" in captured.err
    table = [line.split() for line in captured.out.splitlines() if line.startswith(TASK)]
    assert [t[2:5] for t in table if t[2].isdigit()] == [
        ["0", "trained", "normalised"],
        ["1", "FAILED", "RuntimeError:"],
        ["2", "trained", "normalised"],
    ]
    rows = {r["seed"]: r for r in json.loads(out.read_text())["rows"]}
    assert [rows[s]["status"] for s in (0, 1, 2)] == ["ok", "failed", "ok"]
    assert rows[1]["error"] == "RuntimeError: boom" and rows[1]["timesteps"] == 64
    text = page.read_text()
    assert "| PPO | 0.250 ± 0.000 | 1 | 2 seeds, 64 steps, 0 s per seed; seed 1 failed: " in text
    assert "(3 learner runs, 1 of them failed," in text

    calls.clear()  # a rerun retries only the failed run
    monkeypatch.setattr(run, "learner_row", fake_learner(calls))
    assert bench(*argv, "--no-render") == 0 and calls == [1]
    assert bench(*argv, "--no-render", "--resume") == 0 and calls == [1]
    assert bench(*argv, "--no-render", "--retrain") == 0 and calls == [1, 0, 1, 2]
    calls.clear()  # another budget or other hyperparameters are other runs
    assert bench(*argv, "--no-render", "--timesteps", "128") == 0 and calls == [0, 1, 2]
    calls.clear()
    assert bench(*argv, "--no-render", "--timesteps", "128", "--hp", "n_epochs", "2") == 0
    assert calls == [0, 1, 2]
    assert {r["status"] for r in json.loads(out.read_text())["rows"]} == {"ok"}


def test_a_killed_run_keeps_every_finished_row(tmp_path, monkeypatch, capsys):
    import agents.leaderboard.run as run

    out = tmp_path / "rows.json"
    calls: list[int] = []
    monkeypatch.setattr(run, "learner_row", fake_learner(calls, interrupt={2}))
    argv = ["--tasks", TASK, "--algo", "PPO", "--seeds", "4", "--timesteps", "64",
            "--out", str(out), "--no-render"]  # fmt: skip
    assert bench(*argv) == 130
    assert "rerun the same command to resume" in capsys.readouterr().err
    assert sorted(r["seed"] for r in json.loads(out.read_text())["rows"]) == [0, 1]
    assert [p.name for p in tmp_path.iterdir()] == ["rows.json"]  # no temporary file left
    calls.clear()
    monkeypatch.setattr(run, "learner_row", fake_learner(calls))
    assert bench(*argv, "--missing") == 0 and calls == [2, 3]
