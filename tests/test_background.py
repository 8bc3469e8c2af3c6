"""agents/background.py and torch-ppo's evaluations of policy snapshots off the training thread."""

from __future__ import annotations

import json
import sys
import threading
from pathlib import Path

import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py lives at the root

import train
from agents.background import Background
from agents.runs import read_jsonl

TINY = ["attacker", "--algo", "torch-ppo", "--device", "cpu", "--num-envs", "32",
        "--total-timesteps", "1536", "--eval-freq", "384", "--eval-episodes", "2",
        "--final-eval-episodes", "2", "--checkpoint-freq", "384"]  # fmt: skip


def test_jobs_run_in_the_order_they_were_submitted():
    done = []
    with Background(max_pending=3) as jobs:
        for i in range(25):
            jobs.submit(done.append, i)
        jobs.drain()
        assert done == list(range(25))
    assert all(t.name != "background_0" for t in threading.enumerate())  # the worker stopped


def test_submit_waits_for_the_oldest_job_beyond_max_pending():
    done = []
    with Background(max_pending=1) as jobs:
        jobs.submit(done.append, "a")
        jobs.submit(done.append, "b")  # returns only once "a" has run
        assert "a" in done


def test_a_failed_job_is_raised_in_the_caller_and_stops_the_rest():
    done, error = [], OSError(28, "No space left on device")

    def fail():
        raise error

    jobs = Background()
    jobs.submit(done.append, 1)
    jobs.submit(fail)
    with pytest.raises(OSError) as first:
        jobs.drain()
    assert first.value is error
    with pytest.raises(OSError):
        jobs.submit(done.append, 3)  # refused: the run is failing
    jobs.close(wait_only=True)  # no second raise while the caller reports the first
    assert done == [1]


def test_leaving_on_an_exception_waits_for_the_jobs_without_masking_it():
    done = []
    with pytest.raises(KeyError), Background() as jobs:
        jobs.submit(done.append, "written")
        raise KeyError("training failed")
    assert done == ["written"]


def test_max_pending_below_one_is_refused_naming_it():
    with pytest.raises(ValueError, match="max_pending"):
        Background(max_pending=0)


def test_a_snapshot_keeps_its_weights_while_training_changes_the_policy():
    from agents.torch_ppo import ActorCritic, PolicySpec, TorchPolicy

    torch.manual_seed(0)
    policy = TorchPolicy(ActorCritic(PolicySpec(obs_dim=3, kind="discrete", n=4)), seed=5)
    snapshot = policy.snapshot()
    before = {k: v.clone() for k, v in snapshot.model.state_dict().items()}
    with torch.no_grad():
        for p in policy.model.parameters():
            p.add_(1.0)
    after = snapshot.model.state_dict()
    assert all(torch.equal(before[k], after[k]) for k in before)
    assert snapshot.seed == 5 and snapshot.model is not policy.model


def _records(run_dir: Path) -> list[dict]:
    """evaluations.jsonl without the wall times (they differ between any two runs)."""
    return [
        {k: v for k, v in h.items() if k != "train_seconds"}
        for h in read_jsonl(run_dir / "evaluations.jsonl")
    ]


class _Inline:
    """Background's interface, running each job at once (how the evaluations ran before)."""

    def __init__(self, *args, **kwargs):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None

    def submit(self, job, *args):
        job(*args)

    def drain(self):
        pass


def test_deferred_evaluations_record_the_steps_and_scores_of_inline_ones(tmp_path, monkeypatch):
    import agents.torch_ppo_train as runner

    deferred = train.main([*TINY, "--runs-root", str(tmp_path / "deferred")])
    monkeypatch.setattr(runner, "Background", _Inline)
    inline = train.main([*TINY, "--runs-root", str(tmp_path / "inline")])
    records = _records(deferred.run_dir)
    assert [h["timesteps"] for h in records] == [384, 768, 1152, 1536]
    assert records == _records(inline.run_dir)  # same steps, returns and scores
    assert deferred.history == read_jsonl(deferred.run_dir / "evaluations.jsonl")


def test_a_checkpoint_is_written_after_every_evaluation_up_to_its_step(tmp_path, monkeypatch):
    """A kill after any checkpoint write resumes with all the evaluations it covers on disk."""
    import agents.torch_ppo_train as runner

    real_evaluate, real_save = runner.evaluate, runner.save_training_state
    gate, seen = threading.Event(), []

    def slow_evaluate(*args, **kwargs):  # the first evaluation runs until iteration 2 starts
        gate.wait(timeout=60)
        return real_evaluate(*args, **kwargs)

    def save(state, path):
        on_disk = path.parent.parent / "evaluations.jsonl"
        steps = [h["timesteps"] for h in read_jsonl(on_disk)] if on_disk.exists() else []
        seen.append((state.timesteps, steps))
        return real_save(state, path)

    def stepped(*args, **kwargs):  # the first checkpoint is queued while its evaluation runs
        log = kwargs["log"]

        def logged(record, policy):
            if record["timesteps"] >= 768:
                gate.set()
            log(record, policy)

        return real_train(*args, **{**kwargs, "log": logged})

    real_train = runner.train_torch_ppo
    monkeypatch.setattr(runner, "evaluate", slow_evaluate)
    monkeypatch.setattr(runner, "save_training_state", save)
    monkeypatch.setattr(runner, "train_torch_ppo", stepped)
    run = train.main([*TINY, "--runs-root", str(tmp_path / "runs")])
    assert [s for s, _ in seen] == [384, 768, 1152, 1536]
    for timesteps, on_disk in seen:
        assert on_disk == [s for s in (384, 768, 1152, 1536) if s <= timesteps]
    assert json.loads((run.run_dir / "scores.json").read_text())["num_timesteps"] == 1536
