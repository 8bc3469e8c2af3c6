"""train.py and agents/: checkpoints that cannot run code, Ctrl-C, option checks, run folders."""

import base64
import json
import os
import pathlib
import pickle
import signal
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

import cloudpickle
import numpy as np
import pytest
import torch
from stable_baselines3 import DQN, PPO, SAC
from stable_baselines3.common.vec_env import DummyVecEnv

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py lives at the root

import train
from agents.checkpoint import (
    UntrustedCheckpointError,
    inside,
    load_model,
    load_replay_buffer,
    save_model,
    save_replay_buffer,
)
from agents.config import Hyperparameters as HP
from agents.config import algo_kwargs, resolved_hyperparameters
from agents.interrupt import Aborted, stop_on_signals
from agents.runs import atomic_write
from agents.training import (
    load_checkpoint,
    read_checkpoint_state,
    save_checkpoint,
    train_prefix,
)

ROOT = Path(__file__).resolve().parent.parent
TINY = ["--no-progress-bar", "--final-eval-episodes", "2", "--eval-episodes", "1"]
TINY_PPO = ["--algo", "PPO", "--n-steps", "64", "--batch-size", "32", "--n-epochs", "1"]
PYTHON = sys.executable


class Evil:
    """Unpickling it creates ``marker`` (what a crafted checkpoint could do instead)."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (pathlib.Path.touch, (pathlib.Path(self.marker),))


def evil_sb3_zip(path: Path, marker: Path) -> Path:
    """An SB3-style .zip whose "data" entry holds a cloudpickled :class:`Evil`."""
    blob = base64.b64encode(cloudpickle.dumps(Evil(marker))).decode()
    data = {"policy_class": {":type:": "<class 'abc.ABCMeta'>", ":serialized:": blob}}
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("data", json.dumps(data))
        zf.writestr("_stable_baselines3_version", "2.9.2")
    return path


def evil_tensor_file(path: Path, marker: Path) -> Path:
    """A torch file (our .pt name) whose pickle builds an :class:`Evil`."""
    torch.save({"state_dicts": {"policy": Evil(marker)}, "variables": {}}, path)
    return path


def run(tmp_path, *args, report=None):
    return train.main([*args, "--runs-root", str(tmp_path / "runs")])


def status(tmp_path, capsys, *args):
    """train.py's exit status and its stderr (whitespace and box characters collapsed)."""
    capsys.readouterr()
    try:
        code = train.cli([*args, "--runs-root", str(tmp_path / "runs")])
    except SystemExit as exc:  # tyro's own option errors
        code = exc.code
    err = capsys.readouterr().err
    return code, " ".join(err.replace("│", " ").split())


@pytest.fixture
def ppo_run(tmp_path):
    """A finished 64-step PPO run (checkpoint at 64 steps)."""
    return run(
        tmp_path, "attacker", *TINY_PPO, "--total-timesteps", "64", "--eval-freq", "0", *TINY
    )


def point_state_at(run_dir: Path, **entries) -> None:
    state_path = run_dir / "checkpoints" / "state.json"
    state = json.loads(state_path.read_text())
    state.update(entries)
    state_path.write_text(json.dumps(state))


# ---------------------------------------------------------------------------- malicious files


def test_resume_never_unpickles_an_sb3_zip_and_trust_is_the_only_way_in(tmp_path, ppo_run):
    marker = tmp_path / "pwned"
    evil_sb3_zip(ppo_run.run_dir / "checkpoints" / "model_64.zip", marker)
    point_state_at(ppo_run.run_dir, model="model_64.zip")
    resume = ["attacker", "--algo", "PPO", "--resume", "--total-timesteps", "128"]
    with pytest.raises(UntrustedCheckpointError, match="--trust-checkpoint"):
        run(tmp_path, *resume)
    assert not marker.exists()
    # negative control: the explicit opt-in is what unpickles it (and so runs its code)
    with pytest.raises(Exception):  # noqa: B017 - the crafted file is not a model
        run(tmp_path, *resume, "--trust-checkpoint")
    assert marker.exists()


def test_a_pickle_in_a_tensor_file_is_refused_before_it_runs(tmp_path, ppo_run):
    marker = tmp_path / "pwned"
    ckpt = ppo_run.run_dir / "checkpoints"
    evil_tensor_file(ckpt / "model_64.pt", marker)
    meta = json.loads((ckpt / "model_64.json").read_text())
    import hashlib

    meta["sha256"] = hashlib.sha256((ckpt / "model_64.pt").read_bytes()).hexdigest()
    (ckpt / "model_64.json").write_text(json.dumps(meta))
    for trust in ([], ["--trust-checkpoint"]):  # a .pt is never unpickled, trusted or not
        with pytest.raises(ValueError, match="not a weights-only torch file"):
            run(tmp_path, "attacker", "--algo", "PPO", "--resume", *trust)
        assert not marker.exists()
    torch.load(ckpt / "model_64.pt", weights_only=False)  # negative control
    assert marker.exists()


def test_replay_buffers_are_never_unpickled(tmp_path):
    env = DummyVecEnv([lambda: __import__("gymnasium").make("fdia_env/SparseAttack-v0")])
    model = DQN("MlpPolicy", env, buffer_size=100, learning_starts=10, seed=0)
    marker = tmp_path / "pwned"
    pkl = tmp_path / "replay_buffer_8.pkl"
    pkl.write_bytes(pickle.dumps(Evil(marker)))
    with pytest.raises(UntrustedCheckpointError, match="--trust-checkpoint"):
        load_replay_buffer(model, pkl, tmp_path)
    npz = tmp_path / "replay_buffer_9.npz"  # an object array: np.save pickles it
    with open(npz, "wb") as fh:
        np.savez(fh, observations=np.array([Evil(marker)], dtype=object))
    with pytest.raises(ValueError, match=r"not a plain \.npz"):
        load_replay_buffer(model, npz, tmp_path)
    assert not marker.exists()
    with np.load(npz, allow_pickle=True) as data:  # negative control
        data["observations"]
    assert marker.exists()


def test_best_model_and_model_loading_refuse_pickles(tmp_path, ppo_run):
    marker = tmp_path / "pwned"
    run_dir = ppo_run.run_dir
    evil_sb3_zip(run_dir / "best_model.zip", marker)
    record = {"timesteps": 32, "score": 1.0, "score_name": "ratio", "model": "best_model.zip"}
    (run_dir / "best.json").write_text(json.dumps(record))
    with pytest.raises(UntrustedCheckpointError, match=r"best_model\.zip"):
        run(tmp_path, "attacker", "--algo", "PPO", "--resume", "--total-timesteps", "128")
    with pytest.raises(UntrustedCheckpointError):
        load_model(run_dir / "best_model.zip", ppo_run.model.get_env(), run_dir, algo="PPO")
    evil_tensor_file(run_dir / "model.pt", marker)
    with pytest.raises(ValueError, match="SHA-256"):
        load_model(run_dir / "model.json", ppo_run.model.get_env(), run_dir)
    assert not marker.exists()


def test_selfplay_policies_are_loaded_safely(tmp_path):
    args = ["game", "--steps-per-iteration", "64", "--n-steps", "32", "--batch-size", "16",
            "--n-epochs", "1", "--no-progress-bar", "--final-eval-episodes", "2"]  # fmt: skip
    first = run(tmp_path, *args, "--iterations", "1")
    state_path = first.run_dir / "state.json"
    state = json.loads(state_path.read_text())
    assert state["policies"] == {"attacker": ["attacker_0.json"], "defender": ["defender_0.json"]}
    marker = tmp_path / "pwned"
    evil_sb3_zip(first.run_dir / "policies" / "attacker_0.zip", marker)
    evil_sb3_zip(first.run_dir / "policies" / "defender_0.zip", marker)
    legacy = {k: v for k, v in state.items() if k != "policies"}  # runs before the safe format
    state_path.write_text(json.dumps(legacy))
    with pytest.raises(UntrustedCheckpointError, match="--trust-checkpoint"):
        run(tmp_path, "game", "--resume", "--iterations", "2")
    escaping = {"attacker": ["/etc/passwd"], "defender": ["defender_0.json"]}
    state_path.write_text(json.dumps({**state, "policies": escaping}))
    with pytest.raises(ValueError, match="outside the run folder"):
        run(tmp_path, "game", "--resume", "--iterations", "2")
    assert not marker.exists()
    state_path.write_text(json.dumps(legacy))
    with pytest.raises(Exception):  # noqa: B017 - negative control: trusted, it is unpickled
        run(tmp_path, "game", "--resume", "--iterations", "2", "--trust-checkpoint")
    assert marker.exists()


def test_trusted_resume_of_an_sb3_zip_checkpoint_continues_in_the_safe_format(tmp_path, ppo_run):
    ckpt = ppo_run.run_dir / "checkpoints"
    ppo_run.model.save(ckpt / "model_64.zip")  # how runs were saved before the safe format
    for suffix in (".json", ".pt"):
        (ckpt / f"model_64{suffix}").unlink()
    point_state_at(ppo_run.run_dir, model="model_64.zip")
    with pytest.raises(UntrustedCheckpointError):
        run(tmp_path, "attacker", "--algo", "PPO", "--resume", "--total-timesteps", "128")
    resumed = run(tmp_path, "attacker", "--algo", "PPO", "--resume", "--total-timesteps", "128",
                  "--trust-checkpoint")  # fmt: skip
    assert resumed.model.num_timesteps == 128 and resumed.model._n_updates == 2
    state = json.loads((ckpt / "state.json").read_text())
    assert state["model"] == "model_128.json"  # new checkpoints are safe ones


@pytest.mark.parametrize("kind", ["absolute", "dotdot", "symlink"])
def test_model_paths_outside_the_run_folder_are_refused(tmp_path, ppo_run, kind):
    run_dir, ckpt = ppo_run.run_dir, ppo_run.run_dir / "checkpoints"
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    for suffix in (".json", ".pt"):
        (outside / f"model_64{suffix}").write_bytes((ckpt / f"model_64{suffix}").read_bytes())
    if kind == "absolute":
        name = str(outside / "model_64.json")
    elif kind == "dotdot":
        name = os.path.relpath(outside / "model_64.json", ckpt)
    else:
        (ckpt / "link.json").symlink_to(outside / "model_64.json")
        name = "link.json"
    point_state_at(run_dir, model=name)
    resume = ["attacker", "--algo", "PPO", "--resume", "--trust-checkpoint"]
    with pytest.raises(ValueError, match="outside the run folder") as exc:
        run(tmp_path, *resume)
    assert str(run_dir.resolve()) in str(exc.value)


def test_inside_accepts_names_in_the_folder_and_symlinks_within_it(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "x.json").write_text("{}")
    (tmp_path / "a" / "y.json").symlink_to(tmp_path / "a" / "x.json")
    assert inside(tmp_path / "a", "y.json", tmp_path) == (tmp_path / "a" / "x.json").resolve()
    with pytest.raises(ValueError, match="must be a file name"):
        inside(tmp_path, "", tmp_path)


# ---------------------------------------------------------------------------- round trips


def _models(tmp_path):
    import gymnasium as gym

    yield (
        "PPO",
        PPO,
        DummyVecEnv([lambda: gym.make("fdia_env/SparseAttack-v0")]),
        HP(n_steps=32, batch_size=16, n_epochs=1),
    )
    yield (
        "DQN",
        DQN,
        DummyVecEnv([lambda: gym.make("fdia_env/SparseAttack-v0")]),
        HP(learning_starts=8, buffer_size=200, batch_size=8, train_freq=1),
    )
    yield (
        "SAC",
        SAC,
        DummyVecEnv([lambda: gym.make("fdia_env/CovarianceAttack-v0")]),
        HP(learning_starts=8, buffer_size=200, batch_size=8),
    )


@pytest.mark.parametrize("which", [0, 1, 2])
def test_checkpoint_round_trip_restores_weights_optimizer_counters_and_buffer(tmp_path, which):
    algo, cls, env, hp = list(_models(tmp_path))[which]
    kwargs = algo_kwargs(algo, hp)
    model = cls("MlpPolicy", env, seed=1, **kwargs)
    model.learn(40)
    folder = tmp_path / "checkpoints"
    save_checkpoint(model, folder, 1.5, algo, resolved_hyperparameters(algo, hp))
    state = read_checkpoint_state(folder, tmp_path)
    assert (state.timesteps, state.train_seconds) == (model.num_timesteps, 1.5)
    loaded = load_checkpoint(state, algo, env, kwargs, tmp_path)
    for name, sd in model.get_parameters().items():
        got = loaded.get_parameters()[name]
        flat_a, flat_b = _flatten(sd), _flatten(got)
        assert flat_a.keys() == flat_b.keys() and flat_a, name
        for k in flat_a:
            a, b = flat_a[k], flat_b[k]
            assert torch.equal(a, b) if isinstance(a, torch.Tensor) else a == b, (name, k)
    for counter in ("num_timesteps", "_n_updates", "_episode_num", "_n_calls", "exploration_rate"):
        if hasattr(model, counter):
            assert getattr(loaded, counter) == getattr(model, counter), counter
    if algo == "SAC":
        assert torch.equal(loaded.log_ent_coef, model.log_ent_coef)
    if algo != "PPO":
        rb, lb = model.replay_buffer, loaded.replay_buffer
        assert (lb.pos, lb.full) == (rb.pos, rb.full) == (40, False)
        for name in ("observations", "actions", "rewards", "dones", "next_observations"):
            assert np.array_equal(getattr(lb, name), getattr(rb, name)), name
    obs = env.reset()
    np.testing.assert_array_equal(
        loaded.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0]
    )


def _flatten(d, prefix=""):
    out = {}
    items = d.items() if isinstance(d, dict) else enumerate(d)
    for k, v in items:
        if isinstance(v, dict | list | tuple):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def test_save_model_files_hold_only_tensors_and_json(tmp_path):
    import gymnasium as gym

    env = DummyVecEnv([lambda: gym.make("fdia_env/SparseAttack-v0")])
    model = PPO("MlpPolicy", env, n_steps=32, batch_size=16, seed=0)
    meta_path = save_model(model, tmp_path / "m.json", "PPO", resolved_hyperparameters("PPO", HP()))
    meta = json.loads(meta_path.read_text())
    assert meta["format"] == "fdia_env-sb3-state-v1" and meta["tensors"] == "m.pt"
    payload = torch.load(tmp_path / "m.pt", weights_only=True)  # would raise on other objects
    assert set(payload["state_dicts"]) == {"policy", "policy.optimizer"}


def test_replay_buffer_npz_stores_the_filled_rows_only(tmp_path):
    import gymnasium as gym

    env = DummyVecEnv([lambda: gym.make("fdia_env/SparseAttack-v0")])
    model = DQN("MlpPolicy", env, buffer_size=1000, learning_starts=100, seed=0)
    model.learn(30)
    path = save_replay_buffer(model.replay_buffer, tmp_path / "rb.npz")
    with np.load(path, allow_pickle=False) as data:
        assert model.num_timesteps == 32  # train_freq 4: 30 steps rounded up
        assert data["observations"].shape == (32, 1, 5)  # not the 1000 rows allocated
        assert data["pos"].item() == 32 and not data["full"].item()


def test_resume_continues_with_the_exact_saved_weights(tmp_path, ppo_run):
    saved = {k: v.clone() for k, v in ppo_run.model.policy.state_dict().items()}
    resumed = run(tmp_path, "attacker", "--algo", "PPO", "--resume", "--total-timesteps", "64")
    assert resumed.resumed and resumed.model.num_timesteps == 64
    for k, v in resumed.model.policy.state_dict().items():
        assert torch.equal(v, saved[k]), k
    longer = run(tmp_path, "attacker", "--algo", "PPO", "--resume", "--total-timesteps", "128")
    assert longer.model.num_timesteps == 128 and longer.model._n_updates == 2  # 1 epoch × 2


def test_tensorboard_ranges_do_not_overlap_after_a_resume(tmp_path):
    from tensorboard.backend.event_processing.event_file_loader import EventFileLoader

    first = run(tmp_path, "attacker", *TINY_PPO, "--total-timesteps", "192",
                "--checkpoint-freq", "64", "--eval-freq", "0", *TINY)  # fmt: skip
    point_state_at(first.run_dir, model="model_128.json", timesteps=128)  # as if killed at 192
    before = set((first.run_dir / "tb").glob("events.*"))
    time.sleep(1.1)  # event file names hold the time in seconds
    second = run(tmp_path, "attacker", "--algo", "PPO", "--resume", "--total-timesteps", "256")
    assert second.model.num_timesteps == 256
    (new,) = set((first.run_dir / "tb").glob("events.*")) - before
    events = list(EventFileLoader(str(new)).Load())
    starts = [e.step for e in events if e.HasField("session_log")]
    assert starts == [129]  # TensorBoard hides the earlier files' events from step 129 on
    steps = [e.step for e in events if e.HasField("summary")]
    assert steps and min(steps) == 192 and max(steps) == 256
    old_steps = {e.step for f in before for e in EventFileLoader(str(f)).Load() if e.summary.value}
    assert max(old_steps) == 192  # the orphaned range the purge marker covers


# ---------------------------------------------------------------------------- option checks


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--torch-threads", "0"], "torch_threads (--torch-threads) must be >= 1, got 0"),
        (["--learning-rate", "-1"], "learning_rate (--learning-rate) must be > 0, got -1.0"),
        (["--n-steps", "0"], "n_steps (--n-steps) must be >= 1, got 0"),
        (["--n-steps", "1"], "n_steps (--n-steps) must be >= 2 for PPO"),
        (["--batch-size", "0"], "batch_size (--batch-size) must be >= 1, got 0"),
        (["--eval-episodes", "0"], "eval_episodes (--eval-episodes) must be >= 1, got 0"),
        (["--seed", "-1"], "seed (--seed) must be in [0, 4294967295], got -1"),
        (["--seed", str(2**64)], "seed (--seed) must be in [0, 4294967295]"),
        (["--gamma", "5"], "gamma (--gamma) must be in (0, 1], got 5.0"),
        (["--gamma", "0"], "gamma (--gamma) must be in (0, 1], got 0.0"),
        (["--env-kwargs", "bogus", "3"], "--env-kwargs): unknown option(s) 'bogus'"),
        (["--env-kwargs", "budget", "-3"], "--env-kwargs): fdia_env/SparseAttack-v2 rejected"),
        (["--env-kwargs", "scenario", "ch4-random"], "must not set scenario; pass it with"),
        (["--device", "gpu"], "device (--device) must be cpu, cuda, cuda:<index>, mps or auto"),
        (["--total-timesteps", "0"], "total_timesteps (--total-timesteps) must be >= 1"),
    ],
)
def test_bad_options_fail_before_any_run_folder_exists(tmp_path, capsys, args, message):
    code, err = status(tmp_path, capsys, "attacker", *TINY_PPO, "--total-timesteps", "64", *args)
    assert code == 2
    assert message in err
    assert "Traceback" not in err
    assert not (tmp_path / "runs").exists()  # no run folder, not even the runs root
    code, err = status(tmp_path, capsys, "attacker", "--algo", "PPO", "--resume")
    assert code == 2 and "nothing to resume" in err


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has CUDA")
def test_cuda_without_cuda_is_an_error(tmp_path, capsys):
    code, err = status(tmp_path, capsys, "attacker", *TINY_PPO, "--device", "cuda")
    assert code == 2 and "CUDA is not available here" in err and "--device cpu" in err
    assert not (tmp_path / "runs").exists()


def test_env_kwargs_errors_list_the_valid_options(tmp_path, capsys):
    code, err = status(tmp_path, capsys, "game", "--env-kwargs", "bogus", "3")
    assert code == 2
    assert "valid options: scenario, power, allocation, rounds, reward_mode, dynamics" in err
    assert not (tmp_path / "runs").exists()


def test_resume_skips_folders_without_a_checkpoint(tmp_path, capsys, ppo_run):
    prefix = train_prefix(train.parse(["attacker", "--algo", "PPO"]))
    empty = tmp_path / "runs" / f"{prefix}-29991231-235959"  # newer, but never checkpointed
    empty.mkdir()
    (empty / "config.json").write_text((ppo_run.run_dir / "config.json").read_text())
    resumed = run(tmp_path, "attacker", "--algo", "PPO", "--resume", "--total-timesteps", "64")
    assert resumed.run_dir == ppo_run.run_dir
    assert f"resuming {ppo_run.run_dir} from its checkpoint at 64 steps" in capsys.readouterr().out
    # named by --run-dir, a run killed before its first checkpoint starts again from step 0
    again = run(tmp_path, "attacker", "--algo", "PPO", "--resume", "--run-dir", str(empty),
                "--total-timesteps", "64")  # fmt: skip
    assert again.run_dir == empty and again.model.num_timesteps == 64
    assert f"resuming {empty}: it has no checkpoint" in capsys.readouterr().out


def test_corrupt_state_and_missing_model_name_the_file(tmp_path, capsys, ppo_run):
    state_path = ppo_run.run_dir / "checkpoints" / "state.json"
    good = state_path.read_text()
    state_path.write_text("{not json")
    code, err = status(tmp_path, capsys, "attacker", "--algo", "PPO", "--resume")
    assert code == 2 and f"checkpoint state {state_path} is corrupt" in err
    state_path.write_text(good.replace("model_64.json", "model_10000.json"))
    code, err = status(tmp_path, capsys, "attacker", "--algo", "PPO", "--resume")
    missing = ppo_run.run_dir.resolve() / "checkpoints" / "model_10000.json"
    assert code == 2 and f"{missing}, named by {state_path}, does not exist" in err
    assert ".zip.zip" not in err


def test_the_largest_seed_trains(tmp_path):
    result = run(tmp_path, "attacker", *TINY_PPO, "--total-timesteps", "64", "--eval-freq", "32",
                 "--seed", str(2**32 - 1), *TINY)  # fmt: skip
    assert result.model.num_timesteps == 64 and result.run_dir.name.startswith(
        "sparse_attack_v2-PPO-s4294967295-"
    )


# ---------------------------------------------------------------------------- files


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_atomic_writes_respect_the_umask(tmp_path, umask):
    old = os.umask(umask)
    try:
        atomic_write(tmp_path / "atomic", lambda fh: fh.write(b"x"))
        with open(tmp_path / "plain", "wb") as fh:
            fh.write(b"x")
    finally:
        os.umask(old)
    mode = (tmp_path / "atomic").stat().st_mode & 0o777
    assert mode == (tmp_path / "plain").stat().st_mode & 0o777 == 0o666 & ~umask


def test_stale_temporary_files_are_removed_on_resume(tmp_path, capsys, ppo_run):
    ckpt = ppo_run.run_dir / "checkpoints"
    stale = ckpt / ".model_128.pt.k2j4_9zq.tmp"  # what a kill during atomic_write leaves
    stale.write_bytes(b"partial")
    kept = ckpt / "notes.tmp"  # not one of ours
    kept.write_text("mine")
    run(tmp_path, "attacker", "--algo", "PPO", "--resume", "--total-timesteps", "64")
    assert not stale.exists() and kept.exists()
    assert f"removed a temporary file left by an interrupted write: {stale}" in (
        capsys.readouterr().out
    )


def test_a_run_folder_in_use_cannot_be_resumed(tmp_path, ppo_run):
    import fcntl

    with open(ppo_run.run_dir / ".lock", "r+") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        # flock locks are per open file: a second open in this process conflicts too
        with pytest.raises(ValueError, match="is in use by another process"):
            run(tmp_path, "attacker", "--algo", "PPO", "--resume", "--total-timesteps", "128")


# ---------------------------------------------------------------------------- signals


def test_signal_handlers_are_restored_and_a_second_signal_aborts():
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    with stop_on_signals(report=None) as stop:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.05)
        assert stop.signum == signal.SIGTERM
        with pytest.raises(Aborted):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1)
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before


def _wait_for(folder: Path, pattern: str, min_size: int = 0, timeout: float = 120) -> Path:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = [p for p in folder.glob(pattern) if p.stat().st_size > min_size]
        if found:
            return found[0]
        time.sleep(0.1)
    raise AssertionError(f"no {pattern} in {folder} after {timeout} s")


def _sigint_when(folder: Path, pattern: str, min_size: int = 0) -> threading.Thread:
    """A thread that sends this process SIGINT once ``folder`` holds ``pattern``."""

    def watch():
        _wait_for(folder, pattern, min_size)
        os.kill(os.getpid(), signal.SIGINT)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


def test_sigint_in_process_stops_training_and_writes_the_checkpoint(tmp_path):
    before = signal.getsignal(signal.SIGINT)
    watcher = _sigint_when(tmp_path / "runs", "*/tb/events.*", min_size=2000)  # a few rollouts
    result = run(tmp_path, "attacker", *TINY_PPO, "--total-timesteps", "10000000",
                 "--eval-freq", "0", "--checkpoint-freq", "0", *TINY)  # fmt: skip
    watcher.join()
    assert result.interrupted == signal.SIGINT
    assert 0 < result.model.num_timesteps < 10_000_000
    state = json.loads((result.run_dir / "checkpoints" / "state.json").read_text())
    assert state["timesteps"] == result.model.num_timesteps
    assert signal.getsignal(signal.SIGINT) is before


def test_sigint_stops_self_play_after_the_last_finished_iteration(tmp_path):
    watcher = _sigint_when(tmp_path / "runs", "*/state.json")  # the first iteration is done
    result = run(tmp_path, "game", "--steps-per-iteration", "64", "--n-steps", "32",
                 "--batch-size", "16", "--n-epochs", "1", "--no-progress-bar",
                 "--final-eval-episodes", "2", "--iterations", "100000")  # fmt: skip
    watcher.join()
    assert result.interrupted == signal.SIGINT
    done = len(result.history)
    assert 1 <= done < 100_000
    state = json.loads((result.run_dir / "state.json").read_text())
    assert len(state["history"]) == done and len(state["policies"]["attacker"]) == done
    assert json.loads((result.run_dir / "scores.json").read_text())["iterations"] == done
    more = run(tmp_path, "game", "--resume", "--iterations", str(done + 1))
    assert [h["iteration"] for h in more.history] == list(range(1, done + 2))


def _train_subprocess(tmp_path, *extra):
    args = [PYTHON, str(ROOT / "train.py"), "attacker", *TINY_PPO, "--total-timesteps",
            "100000000", "--eval-freq", "0", "--checkpoint-freq", "0",
            "--runs-root", str(tmp_path / "runs"), *TINY, *extra]  # fmt: skip
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.Popen(
        args, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:  # progress: TensorBoard has logged a few rollouts
        _wait_for(tmp_path / "runs", "*/tb/events.*", min_size=2000)
    except AssertionError:
        proc.kill()
        raise
    return proc


def test_ctrl_c_writes_a_final_checkpoint_and_scores_and_exits_130(tmp_path):
    proc = _train_subprocess(tmp_path)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    (run_dir,) = (tmp_path / "runs").iterdir()
    state = json.loads((run_dir / "checkpoints" / "state.json").read_text())
    scores = json.loads((run_dir / "scores.json").read_text())
    assert 0 < state["timesteps"] == scores["num_timesteps"] < 100_000_000
    assert scores["interrupted"] == signal.SIGINT
    assert (run_dir / "model.json").is_file()
    assert err.strip().splitlines()[-1] == (
        f"train.py: stopped by SIGINT after {state['timesteps']} steps; checkpoint, model and "
        f"scores saved in {run_dir}; continue with: python train.py attacker --resume "
        f"--run-dir {run_dir}"
    )
    assert "(interrupted)" in out
    resumed = run(tmp_path, "attacker", "--algo", "PPO", "--resume", "--run-dir", str(run_dir),
                  "--total-timesteps", str(state["timesteps"] + 64))  # fmt: skip
    assert resumed.model.num_timesteps == state["timesteps"] + 64


def test_a_second_ctrl_c_aborts_at_once_without_a_traceback(tmp_path):
    # a long final evaluation keeps the run busy after the first Ctrl-C
    proc = _train_subprocess(tmp_path, "--final-eval-episodes", "10000000")
    proc.send_signal(signal.SIGINT)
    _wait_for(tmp_path / "runs", "*/model.json")  # the final model is written, evaluation runs
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert "train.py: aborted by a second SIGINT" in err.strip().splitlines()[-1]
    (run_dir,) = (tmp_path / "runs").iterdir()
    assert (run_dir / "checkpoints" / "state.json").is_file()  # written before the evaluation
    assert not (run_dir / "scores.json").exists()
