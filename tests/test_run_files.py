"""Run folders under attack: the lock, kills between writes, crafted files, divergence.

Each test tampers with a copy of a small trained run folder (built once per module) and runs
``train.py ... --resume`` or ``agents.bench score`` on it: the outcome is success or a one-line
error naming the file, never a raw traceback and never a write outside the run folder.
"""

import json
import os
import shutil
import sys
import warnings
from pathlib import Path

import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py lives at the root

import train
from agents.bench.score import main as score_main
from agents.runs import read_jsonl, run_lock

TASK = "sparse/ch4-position-v0"  # train.py's default attacker settings
TINY = ["--no-progress-bar", "--final-eval-episodes", "2", "--eval-episodes", "1"]
TINY_PPO = ["--algo", "PPO", "--n-steps", "64", "--batch-size", "32", "--n-epochs", "1"]
# one iteration of 32 members x 12 steps = 384 env steps
TORCH_PPO = ["--algo", "torch-ppo", "--device", "cpu", "--num-envs", "32",
             "--checkpoint-freq", "384", "--final-eval-episodes", "2"]  # fmt: skip


class Killed(BaseException):
    """Stands for SIGKILL in-process: nothing catches it and no cleanup writes anything."""


@pytest.fixture(scope="module")
def sb3_run(tmp_path_factory):
    """A finished 64-step PPO run, evaluated at 32 and 64 steps (best.json, evaluations)."""
    root = tmp_path_factory.mktemp("sb3")
    argv = ["attacker", *TINY_PPO, "--total-timesteps", "64", "--eval-freq", "32", *TINY]
    return train.main([*argv, "--runs-root", str(root)]).run_dir


@pytest.fixture(scope="module")
def torch_run(tmp_path_factory):
    """A finished one-iteration (384-step) torch-ppo run, evaluated at its end."""
    root = tmp_path_factory.mktemp("torch")
    argv = ["attacker", *TORCH_PPO, "--total-timesteps", "384", "--eval-freq", "384"]
    return train.main([*argv, "--runs-root", str(root)]).run_dir


def copy_run(run_dir: Path, where: Path) -> Path:
    """A copy of ``run_dir`` at ``where/<its name>`` (symlinks kept as links)."""
    return Path(shutil.copytree(run_dir, where / run_dir.name, symlinks=True))


def resume(run_dir: Path, *extra: str):
    return train.main(["attacker", "--resume", "--run-dir", str(run_dir), *extra])


def cli(capsys, *argv: str) -> tuple[int, str]:
    """train.py's exit status and stderr."""
    capsys.readouterr()
    code = train.cli(list(argv))
    return code, capsys.readouterr().err


def rewrite_json(path: Path, **changes) -> None:
    data = json.loads(path.read_text())
    data.update(changes)
    path.write_text(json.dumps(data))


def retensor(description: Path, change) -> None:
    """Apply ``change`` to the payload of the .pt that ``description`` names; fix its SHA-256."""
    import hashlib

    meta = json.loads(description.read_text())
    tensors = description.parent / meta["tensors"]
    payload = torch.load(tensors, weights_only=True)
    change(payload)
    torch.save(payload, tensors)
    meta["sha256"] = hashlib.sha256(tensors.read_bytes()).hexdigest()
    description.write_text(json.dumps(meta))


# ---------------------------------------------------------------------------- the lock


@pytest.mark.parametrize("kind", ["symlink", "hardlink", "foreign"])
def test_the_run_lock_never_writes_through_a_link_or_into_a_foreign_file(tmp_path, kind):
    run_dir, outside = tmp_path / "run", tmp_path / "precious.txt"
    run_dir.mkdir()
    outside.write_text("do not touch\n")
    lock = run_dir / ".lock"
    if kind == "symlink":
        lock.symlink_to(outside)
    elif kind == "hardlink":
        os.link(outside, lock)
    else:
        lock.write_text("some notes\n")
    with pytest.raises(ValueError, match=r"run folder lock .*\.lock is not a lock file"):
        with run_lock(run_dir):
            pass
    assert outside.read_text() == "do not touch\n"
    assert kind != "foreign" or lock.read_text() == "some notes\n"


def test_a_stale_lock_of_a_dead_process_is_taken_over(tmp_path):
    (tmp_path / ".lock").write_text("999999999\n")  # no such process holds it
    with run_lock(tmp_path) as lock:
        assert lock.read_text() == f"{os.getpid()}\n"
    with run_lock(tmp_path):  # and released again
        pass


@pytest.mark.parametrize("backend", ["sb3", "torch"])
def test_resume_never_truncates_the_target_of_a_lock_symlink(
    tmp_path, capsys, sb3_run, torch_run, backend
):
    run_dir = copy_run(sb3_run if backend == "sb3" else torch_run, tmp_path)
    outside = tmp_path / "precious.txt"
    outside.write_text("do not touch\n")
    (run_dir / ".lock").unlink()
    (run_dir / ".lock").symlink_to(outside)
    code, err = cli(capsys, "attacker", "--resume", "--run-dir", str(run_dir))
    assert code == 2 and f"run folder lock {run_dir / '.lock'} is not a lock file" in err
    assert outside.read_text() == "do not touch\n"


# ---------------------------------------------------------------------------- kills


def test_a_kill_between_evaluation_and_checkpoint_loses_no_learning_curve_point(
    tmp_path, monkeypatch
):
    """Killed at the evaluation of step 128, where a checkpoint is due as well."""
    import agents.training as training

    real, calls = training.evaluate, []

    def evaluate(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:  # the evaluation at 128 steps
            raise Killed
        return real(*args, **kwargs)

    monkeypatch.setattr(training, "evaluate", evaluate)
    argv = ["attacker", *TINY_PPO, "--total-timesteps", "192", "--eval-freq", "64",
            "--checkpoint-freq", "64", *TINY, "--runs-root", str(tmp_path / "runs")]  # fmt: skip
    with pytest.raises(Killed):
        train.main(argv)
    monkeypatch.setattr(training, "evaluate", real)
    (run_dir,) = (tmp_path / "runs").iterdir()
    result = resume(run_dir)
    assert result.model.num_timesteps == 192
    steps = [h["timesteps"] for h in read_jsonl(run_dir / "evaluations.jsonl")]
    assert steps == [64, 128, 192]


@pytest.mark.parametrize("backend", ["sb3", "torch"])
def test_a_run_killed_before_its_first_checkpoint_starts_again_from_step_0(
    tmp_path, capsys, sb3_run, torch_run, backend
):
    run_dir = copy_run(sb3_run if backend == "sb3" else torch_run, tmp_path)
    for name in os.listdir(run_dir):  # what a kill before the first checkpoint leaves
        if name not in ("config.json", ".lock", "tb"):
            path = run_dir / name
            shutil.rmtree(path) if path.is_dir() else path.unlink()
    capsys.readouterr()
    result = resume(run_dir)
    out = capsys.readouterr().out
    assert f"resuming {run_dir}: it has no checkpoint" in out
    assert "training starts again from step 0" in out
    steps = result.model.num_timesteps if backend == "sb3" else result.timesteps
    assert steps == (64 if backend == "sb3" else 384)
    assert json.loads((run_dir / "checkpoints" / "state.json").read_text())["timesteps"] == steps


# ---------------------------------------------------------------------------- state files


@pytest.mark.parametrize("value", [-100, 1e30, 10**30, "384", True, None])
def test_a_torch_ppo_state_with_bad_timesteps_is_refused_naming_the_file(
    tmp_path, capsys, torch_run, value
):
    run_dir = copy_run(torch_run, tmp_path)
    state = run_dir / "checkpoints" / "state.json"
    rewrite_json(state, timesteps=value)
    code, err = cli(capsys, "attacker", "--resume", "--run-dir", str(run_dir))
    assert code == 2 and f"{state} is corrupt: timesteps must be an integer in [0, " in err


def test_a_torch_ppo_state_whose_steps_do_not_fit_its_iterations_is_refused(
    tmp_path, capsys, torch_run
):
    run_dir = copy_run(torch_run, tmp_path)
    state = run_dir / "checkpoints" / "state.json"
    rewrite_json(state, timesteps=100)  # 1 iteration of 32 x 12 is 384 steps
    code, err = cli(capsys, "attacker", "--resume", "--run-dir", str(run_dir))
    assert code == 2 and "100 env steps after 1 iterations of 32 x 12" in err


@pytest.mark.parametrize("what", ["model", "state"])
def test_nan_weights_are_refused_naming_the_file_and_tensor(tmp_path, capsys, torch_run, what):
    run_dir = copy_run(torch_run, tmp_path)
    description = run_dir / ("model.json" if what == "model" else "checkpoints/state.json")

    def poison(payload):
        payload["state_dicts"]["policy"]["actor.0.weight"][0, 0] = float("nan")

    retensor(description, poison)
    tensors = description.with_suffix(".pt")
    if what == "model":
        capsys.readouterr()
        assert score_main(["--task", TASK, "--agent", str(run_dir), "--seeds", "1"]) == 2
        err = capsys.readouterr().err
    else:
        code, err = cli(capsys, "attacker", "--resume", "--run-dir", str(run_dir))
        assert code == 2
    assert f"tensor file {tensors.resolve()} holds NaN or infinite weights" in err
    assert "state_dicts.policy.actor.0.weight" in err


# ---------------------------------------------------------------------------- crafted models


def test_a_torch_ppo_model_of_a_huge_network_is_refused_before_allocating(
    tmp_path, capsys, torch_run
):
    run_dir = copy_run(torch_run, tmp_path)
    model = run_dir / "model.json"
    meta = json.loads(model.read_text())
    meta["spec"]["hidden"] = [1_000_000, 1_000_000]  # 4 TB of weights
    model.write_text(json.dumps(meta))
    capsys.readouterr()
    assert score_main(["--task", TASK, "--agent", str(run_dir), "--seeds", "1"]) == 2
    err = capsys.readouterr().err
    assert f"does not hold the network {model.resolve()} describes: actor.0.bias has " in err
    assert "shape (64,), the network needs (1000000,)" in err


@pytest.mark.parametrize(
    "hyperparameters, message",
    [
        ({"net_arch": [1000, 1000]}, "net_arch [1000, 1000] needs at least 1,002,000 weights"),
        ({"net_arch": [100_000]}, "net_arch (100000,) is too large (at most 65536 each)"),
        ({"learning_rate": "fast"}, "learning_rate (--learning-rate) must be a number > 0"),
        ({"not_a_hyperparameter": 3}, "unknown hyperparameter(s) not_a_hyperparameter"),
        ({"gamma": None, "net_arch": "64"}, "net_arch (--net-arch) must be a sequence"),
    ],
)
def test_an_sb3_model_with_bad_hyperparameters_is_refused_naming_file_and_key(
    tmp_path, capsys, sb3_run, hyperparameters, message
):
    run_dir = copy_run(sb3_run, tmp_path)
    model = run_dir / "model.json"
    meta = json.loads(model.read_text())
    meta["hyperparameters"].update(hyperparameters)
    model.write_text(json.dumps(meta))
    capsys.readouterr()
    assert score_main(["--task", TASK, "--agent", str(run_dir), "--seeds", "1"]) == 2
    err = capsys.readouterr().err
    assert str(model.resolve()) in err and message in err


def test_bad_saved_hyperparameters_in_config_json_are_named_on_resume(tmp_path, capsys, sb3_run):
    run_dir = copy_run(sb3_run, tmp_path)
    config = run_dir / "config.json"
    data = json.loads(config.read_text())
    data["resolved"]["hyperparameters"]["bogus"] = 1
    config.write_text(json.dumps(data))
    code, err = cli(capsys, "attacker", "--resume", "--run-dir", str(run_dir))
    assert code == 2
    assert f"{config}: resolved.hyperparameters holds unknown hyperparameter(s) bogus" in err


@pytest.mark.parametrize("content", ["[1, 2]", '{"config": [], "resolved": {}}', ""])
def test_a_config_json_of_the_wrong_shape_is_a_clear_error(tmp_path, capsys, sb3_run, content):
    run_dir = copy_run(sb3_run, tmp_path)
    (run_dir / "config.json").write_text(content)
    code, err = cli(capsys, "attacker", "--resume", "--run-dir", str(run_dir))
    assert code == 2 and f"run config {run_dir / 'config.json'} is corrupt" in err


# ---------------------------------------------------------------------------- logs


@pytest.mark.parametrize("backend", ["sb3", "torch"])
def test_a_corrupt_log_line_is_skipped_with_a_warning_naming_file_and_line(
    tmp_path, sb3_run, torch_run, backend
):
    run_dir = copy_run(sb3_run if backend == "sb3" else torch_run, tmp_path)
    from agents.runs import CorruptLogLine

    log = run_dir / "evaluations.jsonl"
    lines = log.read_text().splitlines()
    log.write_text("\n".join([lines[0], "{'timesteps': 1,", '{"timesteps": "x"}', *lines[1:]]))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = resume(run_dir)
    skipped = [str(w.message) for w in caught if issubclass(w.category, CorruptLogLine)]
    assert skipped[:2] == [
        f"skipped line 2 of {log}: not JSON (Expecting property name enclosed in double quotes: "
        "line 1 column 2 (char 1))",
        f"skipped line 3 of {log}: not a valid record",
    ]
    kept = [json.loads(line) for line in lines]
    assert result.history == kept  # the corrupt lines are gone, the good ones kept as they were
    assert read_jsonl(log) == kept


# ---------------------------------------------------------------------------- divergence


def test_a_diverging_torch_ppo_run_stops_naming_what_and_the_last_good_checkpoint(
    tmp_path, monkeypatch
):
    """A gradient turns NaN in the second iteration: nothing of it is saved."""
    real, calls = torch.nn.utils.clip_grad_norm_, []

    def clip(parameters, *args, **kwargs):
        parameters = list(parameters)
        calls.append(1)
        if len(calls) == 4 * 4 + 1:  # the first minibatch of iteration 2 (4 epochs x 4)
            parameters[0].grad.fill_(float("nan"))
        return real(parameters, *args, **kwargs)

    monkeypatch.setattr(torch.nn.utils, "clip_grad_norm_", clip)
    argv = ["attacker", *TORCH_PPO, "--total-timesteps", "1152", "--eval-freq", "384",
            "--runs-root", str(tmp_path / "runs")]  # fmt: skip
    with pytest.raises(ValueError) as info:
        train.main(argv)
    monkeypatch.setattr(torch.nn.utils, "clip_grad_norm_", real)
    (run_dir,) = (tmp_path / "runs").iterdir()
    state = run_dir / "checkpoints" / "state.json"
    assert str(info.value) == (
        "training diverged at step 768: the gradient is not finite (NaN or infinity); no "
        "checkpoint of the diverged weights was written; the last good checkpoint is "
        f"{state} at 384 steps, which --resume continues (or start a new run with a smaller "
        "--learning-rate)"
    )
    assert json.loads(state.read_text())["timesteps"] == 384
    assert [h["timesteps"] for h in read_jsonl(run_dir / "evaluations.jsonl")] == [384]
    assert resume(run_dir).timesteps == 1152  # the good checkpoint continues


def test_a_diverging_sb3_run_stops_before_checkpointing_the_diverged_weights(tmp_path, monkeypatch):
    from stable_baselines3 import PPO

    real, calls = PPO.train, []

    def poisoned_train(self):
        real(self)
        calls.append(1)
        if len(calls) == 2:  # the update after 128 steps
            with torch.no_grad():
                next(self.policy.parameters()).fill_(float("nan"))

    monkeypatch.setattr(PPO, "train", poisoned_train)
    argv = ["attacker", *TINY_PPO, "--total-timesteps", "256", "--eval-freq", "0",
            "--checkpoint-freq", "64", *TINY, "--runs-root", str(tmp_path / "runs")]  # fmt: skip
    with pytest.raises(ValueError, match=r"^training diverged at step 128: the parameter ") as info:
        train.main(argv)
    monkeypatch.setattr(PPO, "train", real)
    (run_dir,) = (tmp_path / "runs").iterdir()
    state = run_dir / "checkpoints" / "state.json"
    assert f"the last good checkpoint is {state} at 128 steps" in str(info.value)
    assert resume(run_dir).model.num_timesteps == 256  # its weights are finite: it loads


# ---------------------------------------------------------------------------- any corruption

BAD_VALUES = [[], {}, "x", None, True, -1, 10**30, 1e308, float("nan")]


def _leaves(data, path=()):
    """The key paths into a JSON value (every dict entry and list item)."""
    items = data.items() if isinstance(data, dict) else enumerate(data)
    for key, value in items:
        yield (*path, key)
        if isinstance(value, dict | list):
            yield from _leaves(value, (*path, key))


def corrupt(run_dir: Path, data) -> str:
    """Corrupt one file of ``run_dir`` as ``data`` draws; return what was done."""
    from hypothesis import strategies as st

    files = sorted(str(p.relative_to(run_dir)) for p in run_dir.rglob("*") if p.is_file())
    rel = data.draw(st.sampled_from(files), label="file")
    path = run_dir / rel
    kinds = ["truncate", "bytes"]
    if path.suffix == ".json":
        kinds += ["json-value", "json-delete"]
    if path.suffix == ".pt" and path.with_suffix(".json").is_file():
        kinds += ["nan-weights"]
    kind = data.draw(st.sampled_from(kinds), label="kind")
    raw = path.read_bytes()
    if kind == "truncate":
        path.write_bytes(raw[: data.draw(st.integers(0, max(len(raw) - 1, 0)), label="size")])
    elif kind == "bytes":
        path.write_bytes(data.draw(st.binary(min_size=1, max_size=64), label="bytes"))
    elif kind == "nan-weights":

        def poison(payload):
            floats = [
                t
                for sd in payload["state_dicts"].values()
                for t in sd.values()
                if isinstance(t, torch.Tensor) and t.is_floating_point() and t.numel()
            ]
            t = floats[data.draw(st.integers(0, len(floats) - 1), label="tensor")]
            t.view(-1)[0] = float("nan")

        retensor(path.with_suffix(".json"), poison)
    else:
        doc = json.loads(raw)
        leaves = list(_leaves(doc))
        if not leaves:
            path.write_text(json.dumps(data.draw(st.sampled_from(BAD_VALUES))))
            return f"{rel}: replaced"
        key_path = data.draw(st.sampled_from(leaves), label="key")
        parent = doc
        for key in key_path[:-1]:
            parent = parent[key]
        if kind == "json-delete":
            del parent[key_path[-1]]
        else:
            parent[key_path[-1]] = data.draw(st.sampled_from(BAD_VALUES), label="value")
        path.write_text(json.dumps(doc))
        return f"{rel}: {kind} at {key_path}"
    return f"{rel}: {kind}"


def _snapshot(folder: Path, skip: Path) -> dict[str, bytes]:
    return {
        str(p): p.read_bytes()
        for p in folder.rglob("*")
        if p.is_file() and not p.is_relative_to(skip)
    }


def _outcome(call) -> tuple[int, str]:
    """``call()``'s exit status and stderr (-1 and the traceback for an escaping exception)."""
    import contextlib
    import io
    import traceback

    err, out = io.StringIO(), io.StringIO()
    with (
        contextlib.redirect_stderr(err),
        contextlib.redirect_stdout(out),
        warnings.catch_warnings(),
    ):
        warnings.simplefilter("ignore")
        try:
            code = call()
        except Exception:  # the report names the corruption and shows the traceback
            return -1, traceback.format_exc()
    return code, err.getvalue()


def _check_corrupted(run_dir: Path, data, length: int) -> None:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        where = Path(tmp)
        copy = copy_run(run_dir, where)
        (where / "outside").mkdir()
        (where / "outside" / "precious.txt").write_text("do not touch\n")
        before = _snapshot(where, copy)
        what = corrupt(copy, data)
        name = Path(what.split(":")[0]).name
        argv = ["--task", TASK, "--agent", str(copy), "--seeds", "1", "--episodes", "2"]
        resume_argv = ["attacker", "--resume", "--run-dir", str(copy),
                       "--total-timesteps", str(length)]  # fmt: skip
        for label, call in (
            ("score", lambda: score_main(argv)),
            ("resume", lambda: train.cli(resume_argv)),
        ):
            code, err = _outcome(call)
            assert code in (0, 2), f"{what}: {label} exited {code}: {err[-2000:]}"
            assert "Traceback" not in err, f"{what}: {label}: {err[-2000:]}"
            if code:
                message = err.strip().splitlines()[-1]
                assert message.startswith(("error: ", "train.py: error: ")), f"{what}: {message}"
                assert copy.name in message and name in message, (
                    f"{what}: {label} does not name the file: {message}"
                )
        assert _snapshot(where, copy) == before, f"{what}: a file outside the run folder changed"


@pytest.mark.parametrize("backend", ["sb3", "torch"])
def test_any_corruption_of_a_run_file_is_a_clear_error_or_harmless(sb3_run, torch_run, backend):
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    run_dir, length = (sb3_run, 64) if backend == "sb3" else (torch_run, 384)

    @settings(
        max_examples=int(os.environ.get("RUN_FILES_EXAMPLES", "4")),
        deadline=None,
        derandomize="RUN_FILES_EXAMPLES" not in os.environ,
        suppress_health_check=[HealthCheck.too_slow],
        database=None,
    )
    @given(st.data())
    def check(data):
        _check_corrupted(run_dir, data, length)

    check()
