"""Training runs survive kills and full disks, and a resume never shortens a run."""

import errno
import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py lives at the root

import train
from agents import checkpoint as ckpt
from agents.runs import check_not_shorter
from agents.torch_ppo import TrainingState, load_training_state, save_training_state

ROOT = Path(__file__).resolve().parent.parent
TINY = ["--no-progress-bar", "--final-eval-episodes", "2", "--eval-episodes", "1"]
TINY_PPO = ["--algo", "PPO", "--n-steps", "64", "--batch-size", "32", "--n-epochs", "1"]
# 4 iterations of 32 members x 12 steps = 384 env steps each; a checkpoint after every one
TORCH_PPO = ["--algo", "torch-ppo", "--device", "cpu", "--num-envs", "32",
             "--total-timesteps", "1536", "--checkpoint-freq", "384", "--eval-freq", "0",
             "--final-eval-episodes", "2"]  # fmt: skip


class Killed(BaseException):
    """Stands for SIGKILL in-process: nothing catches it and no cleanup writes anything."""


def status(tmp_path, capsys, *args):
    """train.py's exit status and its stderr lines."""
    capsys.readouterr()
    code = train.cli([*args, "--runs-root", str(tmp_path / "runs")])
    return code, [line for line in capsys.readouterr().err.splitlines() if line.strip()]


def state(k: float) -> TrainingState:
    """A small training state whose every tensor holds ``k``."""
    return TrainingState(
        iteration=int(k),
        timesteps=100 * int(k),
        seconds=k,
        model={"w": torch.full((3,), k)},
        optimizer={"state": {}, "param_groups": []},
        generator=torch.full((4,), int(k), dtype=torch.uint8),
        ret_stats=torch.tensor([k, 0.0, 1.0], dtype=torch.float64),
    )


# ---------------------------------------------------------------------------- kills mid-write


def test_a_kill_at_any_point_of_a_checkpoint_write_leaves_a_loadable_state(tmp_path, monkeypatch):
    path = tmp_path / "checkpoints" / "state.json"
    save_training_state(state(1), path)

    def dies(*args, **kwargs):
        raise Killed

    # killed after the new tensors, before the description: the previous state loads
    with monkeypatch.context() as m:
        m.setattr(ckpt, "write_json", dies)
        with pytest.raises(Killed):
            save_training_state(state(2), path)
    assert load_training_state(path, tmp_path).timesteps == 100
    assert float(load_training_state(path, tmp_path).model["w"][0]) == 1.0

    # killed after the description, before the staged tensors moved: the new state loads
    real_replace = os.replace

    def dies_moving_the_staged_file(src, dst):
        if str(src).endswith(ckpt.STAGED):
            raise Killed
        real_replace(src, dst)

    with monkeypatch.context() as m:
        m.setattr(os, "replace", dies_moving_the_staged_file)
        with pytest.raises(Killed):
            save_training_state(state(3), path)
    loaded = load_training_state(path, tmp_path)
    assert (loaded.timesteps, float(loaded.model["w"][0])) == (300, 3.0)

    # killed again in the next write, before its description: still the last described state
    with monkeypatch.context() as m:
        m.setattr(ckpt, "write_json", dies)
        with pytest.raises(Killed):
            save_training_state(state(4), path)
    loaded = load_training_state(path, tmp_path)
    assert (loaded.timesteps, float(loaded.model["w"][0])) == (300, 3.0)

    save_training_state(state(5), path)  # an undisturbed write leaves the plain pair
    assert sorted(p.name for p in path.parent.iterdir()) == ["state.json", "state.pt"]
    assert load_training_state(path, tmp_path).timesteps == 500


def test_a_sigkill_between_the_torch_ppo_checkpoint_writes_keeps_the_run_resumable(tmp_path):
    """The second checkpoint's process dies after its tensors, before its state.json."""
    runs = tmp_path / "runs"
    script = textwrap.dedent(
        f"""
        import os, signal, sys
        sys.path.insert(0, {str(ROOT)!r})
        import agents.runs as runs

        real, seen = runs.write_json, []

        def write_json(path, data):
            if path.name == "state.json":
                seen.append(path)
                if len(seen) == 2:
                    os.kill(os.getpid(), signal.SIGKILL)
            return real(path, data)

        runs.write_json = write_json  # before any module binds it
        import train

        train.main(["attacker", *{TORCH_PPO!r}, "--runs-root", {str(runs)!r}])
        """
    )
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, timeout=240)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()[-2000:]
    (run_dir,) = runs.iterdir()
    assert not (run_dir / "scores.json").exists()
    saved = json.loads((run_dir / "checkpoints" / "state.json").read_text())
    assert saved["timesteps"] == 384  # the first checkpoint's, intact

    resumed = train.main(["attacker", "--resume", "--run-dir", str(run_dir)])
    assert resumed.resumed and resumed.timesteps == 1536
    assert json.loads((run_dir / "scores.json").read_text())["num_timesteps"] == 1536


# ---------------------------------------------------------------------------- full disks


FULL_DISK = {
    "torch": RuntimeError(
        "[enforce fail at inline_container.cc:672] . unexpected pos 4480 vs 4374\n"
        "frame #0: c10::ThrowEnforceNotMet(...)"
    ),
    "os": OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)),
}


@pytest.mark.parametrize("error", sorted(FULL_DISK))
def test_a_full_disk_during_a_resume_is_a_one_line_io_error(tmp_path, capsys, monkeypatch, error):
    base = ["attacker", *TINY_PPO, "--eval-freq", "0", *TINY]
    assert status(tmp_path, capsys, *base, "--total-timesteps", "64")[0] == 0
    (run_dir,) = (tmp_path / "runs").iterdir()
    before = (run_dir / "checkpoints" / "state.json").read_text()

    def full(*args, **kwargs):
        raise FULL_DISK[error]

    with monkeypatch.context() as m:
        m.setattr(torch, "save", full)
        code, err = status(tmp_path, capsys, *base, "--total-timesteps", "128", "--resume")
    assert code == 1, err
    assert len(err) == 1 and err[0].startswith("train.py: error: "), err
    assert "could not write" in err[0] and str(run_dir) in err[0], err
    assert "enforce fail" not in err[0] or error == "torch"
    assert (run_dir / "checkpoints" / "state.json").read_text() == before
    # the run is still resumable once there is room again
    code, err = status(tmp_path, capsys, *base, "--total-timesteps", "128", "--resume")
    assert code == 0, err
    assert json.loads((run_dir / "scores.json").read_text())["num_timesteps"] == 128


def test_a_full_disk_writing_json_names_the_file(tmp_path, monkeypatch):
    from agents.runs import write_json

    real = os.fsync

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError, match=r"could not write .*scores\.json: No space left") as exc:
        write_json(tmp_path / "scores.json", {"a": 1})
    assert exc.value.errno == errno.ENOSPC
    monkeypatch.setattr(os, "fsync", real)
    assert list(tmp_path.iterdir()) == []  # no temporary file left behind


# ---------------------------------------------------------------------------- training length


def test_a_resume_below_the_trained_steps_is_refused_naming_the_option(tmp_path, capsys):
    base = ["attacker", *TINY_PPO, "--eval-freq", "0", *TINY]
    assert status(tmp_path, capsys, *base, "--total-timesteps", "128")[0] == 0
    (run_dir,) = (tmp_path / "runs").iterdir()
    files = {p: p.read_bytes() for p in (run_dir / "scores.json", run_dir / "model.pt")}
    code, err = status(tmp_path, capsys, *base, "--total-timesteps", "64", "--resume")
    assert code == 2
    assert err == [
        f"train.py: error: --total-timesteps 64 is below the 128 steps {run_dir} has trained "
        "already: a resume continues a run and cannot shorten it; give --total-timesteps 128 "
        "or more, or start a new run"
    ]
    assert all(p.read_bytes() == data for p, data in files.items())  # nothing rewritten
    # the run's own length re-scores it; a longer one continues it
    assert status(tmp_path, capsys, *base, "--total-timesteps", "128", "--resume")[0] == 0
    assert status(tmp_path, capsys, *base, "--total-timesteps", "192", "--resume")[0] == 0
    assert json.loads((run_dir / "scores.json").read_text())["num_timesteps"] == 192


def test_a_torch_ppo_resume_below_the_trained_steps_is_refused(tmp_path):
    argv = ["attacker", *TORCH_PPO[:-4], "--final-eval-episodes", "2"]
    argv[argv.index("--total-timesteps") + 1] = "384"
    first = train.main([*argv, "--runs-root", str(tmp_path / "runs")])
    assert first.timesteps == 384
    short = ["attacker", "--resume", "--run-dir", str(first.run_dir)]
    with pytest.raises(ValueError, match=r"^--total-timesteps 100 is below the 384 steps"):
        train.main([*short, "--total-timesteps", "100"])
    assert train.main(short).timesteps == 384  # its own length: nothing to train, re-scored


def test_the_length_check_accepts_a_finished_runs_own_length():
    saved = {"total_timesteps": 100, "iterations": 3}
    check_not_shorter("total_timesteps", 100, 128, saved, Path("r"))  # the last rollout overshot
    check_not_shorter("total_timesteps", 128, 128, saved, Path("r"))
    check_not_shorter("iterations", 3, 3, saved, Path("r"), "iterations")
    with pytest.raises(ValueError, match=r"--total-timesteps 99 is below the 128 steps r has"):
        check_not_shorter("total_timesteps", 99, 128, saved, Path("r"))
    with pytest.raises(ValueError, match=r"--iterations 2 is below the 3 iterations .*--iter"):
        check_not_shorter("iterations", 2, 3, saved, Path("r"), "iterations")
    with pytest.raises(ValueError, match="give --total-timesteps 64 or more"):
        check_not_shorter("total_timesteps", 10, 64, {"total_timesteps": 1000}, Path("r"))


def test_a_game_resume_below_the_finished_iterations_is_refused(tmp_path, capsys):
    game = ["game", "--method", "fsp", "--steps-per-iteration", "64", *TINY_PPO, *TINY[:3]]
    assert status(tmp_path, capsys, *game, "--iterations", "2")[0] == 0
    (run_dir,) = (tmp_path / "runs").iterdir()
    scores = (run_dir / "scores.json").read_bytes()
    code, err = status(tmp_path, capsys, *game, "--iterations", "1", "--resume")
    assert code == 2
    assert err == [
        f"train.py: error: --iterations 1 is below the 2 iterations {run_dir} has trained "
        "already: a resume continues a run and cannot shorten it; give --iterations 2 or more, "
        "or start a new run"
    ]
    assert (run_dir / "scores.json").read_bytes() == scores
