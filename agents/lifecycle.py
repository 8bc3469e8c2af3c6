"""One training run's lifecycle, shared by every driver (SB3, torch PPO, self-play, RLlib).

A driver checks its options and builds what it trains, then:

1. :func:`open_run` finds the run folder: a new one's path (not created yet), or, with
   ``--resume``, the folder to continue (``--run-dir``, or the latest of this prefix holding the
   driver's checkpoint marker). A resumed folder is locked at once, its ``config.json`` must
   agree with the given options (its ``--task`` included; except the training length and how
   the run executes: :data:`agents.runs.RESUMABLE`), and the temporary files a kill left are
   removed;
2. :meth:`RunFolder.check_not_shorter` refuses a resume that would shorten the run;
3. :meth:`RunFolder.begin` creates and locks a new folder (removed again if the launch fails
   before its first checkpoint), once the model is built;
4. :meth:`RunFolder.write_config` writes ``config.json`` (the options and what they resolved
   to); :meth:`RunFolder.resume_seed` gives the fresh seed of a resumed run;
5. :meth:`RunFolder.watch_signals` makes the first SIGINT/SIGTERM a stop request (training
   ends after the current step or iteration, the final checkpoint and scores are written) and
   a second one an :class:`~agents.interrupt.Aborted`;
6. :meth:`RunFolder.write_scores` writes ``scores.json``; :func:`tensorboard` is the SB3
   logger writing ``tb/`` (with the purge marker that keeps a resumed run's step ranges apart;
   nothing, after a one-time notice, without the ``tensorboard`` extra).

Every cleanup (lock, signal handlers, removal of a failed new folder) is registered on the
driver's :class:`~contextlib.ExitStack`.
"""

from __future__ import annotations

import functools
import importlib.util
import shutil
import sys
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from agents.checkpoint import read_json
from agents.interrupt import Diverged, StopRequest, stop_on_signals
from agents.runs import (
    check_not_shorter,
    check_resumable,
    config_dict,
    new_run_dir,
    read_jsonl,
    remove_stale_temp_files,
    removed_unless,
    resume_dir,
    run_lock,
    write_json,
    write_jsonl,
)
from agents.seeding import derived_seed

if TYPE_CHECKING:
    from agents.evaluate import Evaluation

SCORES = "scores.json"
EVALUATIONS = "evaluations.jsonl"


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def is_evaluation(record: dict[str, Any]) -> bool:
    """Whether an ``evaluations.jsonl`` record has what the learning curve and a resume read.

    Its ``timesteps`` an integer >= 0, its ``mean`` a number and its ``ci95`` a number or null.
    """
    steps, ci95 = record.get("timesteps"), record.get("ci95")
    return (
        isinstance(steps, int)
        and not isinstance(steps, bool)
        and steps >= 0
        and _number(record.get("mean"))
        and (ci95 is None or _number(ci95))
    )


def _silent(line: str) -> None:
    return None


@dataclass
class RunResult:
    """What a training driver (torch PPO, RLlib) returns; each adds its policy, keyword-only.

    Attributes:
        run_dir: The run folder.
        evaluations: Final evaluations by row name, as printed and in scores.json.
        history: Records during training (evaluations, or one per iteration).
        timesteps: Env steps trained.
        train_seconds: Wall time of training (across resumes).
        resumed: Whether the run continued a saved state.
        interrupted: The signal that stopped training early, or None.
    """

    run_dir: Path
    evaluations: dict[str, Evaluation]
    history: list[dict[str, Any]] = field(default_factory=list)
    timesteps: int = 0
    train_seconds: float = 0.0
    resumed: bool = False
    interrupted: int | None = None


@dataclass
class RunFolder:
    """The folder a run trains in, new or resumed, and its lifecycle steps.

    Attributes:
        path: The run folder (a new run's does not exist until :meth:`begin`).
        marker: The file (relative to ``path``) a resumable run holds: its checkpoint.
        stack: The driver's exit stack, which releases the lock and signal handlers.
        saved: A resumed run's saved options (``config.json``'s ``config``); None: a new run.
        saved_resolved: A resumed run's ``config.json`` ``resolved`` entry.
        stop: The stop request, once :meth:`watch_signals` was called.
    """

    path: Path
    marker: str
    stack: ExitStack
    saved: dict[str, Any] | None = None
    saved_resolved: dict[str, Any] = field(default_factory=dict)
    stop: StopRequest = field(default_factory=StopRequest)

    @property
    def resumed(self) -> bool:
        """Whether the run continues a saved one."""
        return self.saved is not None

    @property
    def checkpointed(self) -> bool:
        """Whether a resumed run has a checkpoint (False: it starts again from step 0)."""
        return self.resumed and (self.path / self.marker).is_file()

    def last_checkpoint(self) -> str | None:
        """The run's checkpoint as one phrase (``<path> at <N> steps``), or None: none yet."""
        path = self.path / self.marker
        try:
            steps = read_json(path, "checkpoint").get("timesteps")
        except ValueError:
            return None
        return f"{path} at {steps} steps"

    def diverged(self, exc: Diverged) -> Diverged:
        """``exc`` naming the run's last good checkpoint (:meth:`last_checkpoint`)."""
        return Diverged(exc.what, exc.step, self.last_checkpoint())

    def restart_note(self) -> str:
        """The line a resume of a run without a checkpoint prints."""
        return (
            f"resuming {self.path}: it has no checkpoint ({self.marker}; it was stopped before "
            "its first), so training starts again from step 0"
        )

    def check_not_shorter(self, name: str, given: int, done: int, unit: str = "steps") -> None:
        """On a resume, refuse ``--<name> given`` below the ``done`` the run has trained.

        Raises:
            ValueError: As :func:`agents.runs.check_not_shorter`.
        """
        if self.saved is not None:
            check_not_shorter(name, given, done, self.saved, self.path, unit)

    def resume_seed(self, seed: int, done: int) -> int:
        """The run's seed, or after a resume at ``done`` steps a fresh one derived from it."""
        return derived_seed(seed, done) if self.checkpointed else seed

    def begin(self) -> Path:
        """Create and lock a new run's folder (nothing to do for a resumed one).

        The folder is removed if the driver's block raises before :attr:`marker` exists.
        """
        if not self.resumed:
            self.path.mkdir(parents=True)
            self.stack.enter_context(removed_unless(self.path, self.marker))
            self.stack.enter_context(run_lock(self.path))
        return self.path

    def discard(self) -> None:
        """A new run stopped before it saved anything: release it and remove its folder."""
        if not self.resumed:
            self.stack.close()
            shutil.rmtree(self.path, ignore_errors=True)

    def evaluations(self, upto: int) -> list[dict[str, Any]]:
        """The run's ``evaluations.jsonl`` up to step ``upto``, rewritten without the rest.

        The evaluations after the checkpoint a run continues from belong to the training it
        repeats; they are dropped (and done again). A corrupt line is skipped with a warning
        (:func:`agents.runs.read_jsonl`).
        """
        path = self.path / EVALUATIONS
        history = [h for h in read_jsonl(path, is_evaluation) if h["timesteps"] <= upto]
        write_jsonl(path, history)
        return history

    def write_config(self, command: str, cfg: Any, resolved: dict[str, Any]) -> Path:
        """Write ``config.json``: the command, the options given and what they resolved to."""
        return write_json(
            self.path / "config.json",
            {"command": command, "config": config_dict(cfg), "resolved": resolved},
        )

    def watch_signals(self) -> StopRequest:
        """Handle SIGINT/SIGTERM until the driver's block ends (:mod:`agents.interrupt`)."""
        self.stop = self.stack.enter_context(stop_on_signals())
        return self.stop

    def write_scores(self, fields: dict[str, Any], evaluations: dict[str, Any]) -> Path:
        """Write ``scores.json``: ``fields``, the stop signal and the evaluations by row name.

        ``interrupted`` is the signal that stopped training, or None.
        """
        return write_json(
            self.path / SCORES,
            {
                **fields,
                "interrupted": self.stop.signum,
                "evaluations": {k: v.to_dict() for k, v in evaluations.items()},
            },
        )


def game_scores(
    method: str,
    value: float,
    x: Any,
    y: Any,
    history: list[dict[str, Any]],
    timesteps: int,
    train_seconds: float,
    **fields: Any,
) -> dict[str, Any]:
    """The ``scores.json`` fields of a matrix-game run (self-play or a population loop).

    Args:
        method: ``"selfplay"``, ``"ibr"``, ``"fsp"`` or ``"psro"``.
        value: The game's value.
        x: The defender's final mix.
        y: The attacker's final mix.
        history: The iteration records (non-empty; the last one's exploitability is scored).
        timesteps: The env steps trained.
        train_seconds: The training time.
        **fields: More fields (the backend, the populations), placed after ``y``.

    Example:
        >>> import numpy as np
        >>> rec = {"defender": 1.0, "attacker": 1.5, "nash_conv": 0.5, "relative_nash_conv": 0.25}
        >>> scores = game_scores("fsp", 2.0, np.ones(2) / 2, np.ones(3) / 3, [rec], 64, 1.5)
        >>> scores["final"], scores["iterations"], list(scores)[-2:]
        ({'defender': 1.0, 'attacker': 1.5, 'nash_conv': 0.5}, 1, ['timesteps', 'train_seconds'])
    """
    last = history[-1]
    return {
        "method": method,
        "value": value,
        "x": np.asarray(x).tolist(),
        "y": np.asarray(y).tolist(),
        **fields,
        "final": {k: last[k] for k in ("defender", "attacker", "nash_conv")},
        "relative_nash_conv": last["relative_nash_conv"],
        "iterations": len(history),
        "timesteps": timesteps,
        "train_seconds": train_seconds,
    }


def run_name(env: str, agent: str) -> str:
    """A run folder's env part: ``<env>`` for the attacker, ``<env>-<agent>`` otherwise."""
    return env if agent == "attacker" else f"{env}-{agent}"


def open_run(
    cfg: Any,
    stack: ExitStack,
    prefix: str,
    marker: str,
    report: Callable[[str], None] | None = print,
    backend: str | None = None,
    fresh: bool = False,
) -> RunFolder:
    """The run folder of ``cfg``: a new one's path (not created), or the one ``--resume`` picks.

    On resume the folder is locked (on ``stack``), its ``config.json`` checked against ``cfg``
    and the temporary files of an interrupted write removed (each reported).

    Args:
        cfg: The command's options (a dataclass with a ``run`` of
            :class:`~agents.config.RunSettings`).
        stack: The driver's exit stack.
        prefix: The run folder name without its time (``<env>-<algo>-s<seed>``).
        marker: The checkpoint file a resumable folder holds (relative to it).
        report: Called with one line per removed temporary file (None: silent).
        backend: When given, a resumed folder must have been written by this backend.
        fresh: Also resume a run without a checkpoint (killed before its first), which the
            driver starts again from step 0 (:attr:`RunFolder.checkpointed` is False).

    Raises:
        ValueError: Nothing to resume, a folder in use, a run of another backend, another
            ``--task`` than the run's (:func:`check_same_task`), options that differ from the
            saved ones, or a corrupt config.json.
        FileExistsError: When a new run's folder exists.
    """
    say = report or _silent
    if not cfg.run.resume:
        return RunFolder(new_run_dir(cfg.run.runs_root, cfg.run.run_dir, prefix), marker, stack)
    run_dir = resume_dir(cfg.run.runs_root, cfg.run.run_dir, prefix, marker, fresh)
    stack.enter_context(run_lock(run_dir))
    config_path = run_dir / "config.json"
    saved = read_json(config_path, "run config")
    resolved = saved.get("resolved") or {}
    options = saved.get("config", {})
    for key, value in (("resolved", resolved), ("config", options)):
        if not isinstance(value, dict):
            raise ValueError(
                f"run config {config_path} is corrupt: {key} must be a JSON object, got "
                f"{value!r:.80}"
            )
    if backend is not None and resolved.get("backend", "sb3") != backend:
        raise ValueError(
            f"cannot resume {run_dir} with --backend {backend}: it is not an "
            f"{'RLlib' if backend == 'rllib' else backend} run"
        )
    check_same_task(options.get("task"), getattr(cfg, "task", None), run_dir)
    check_resumable(options, config_dict(cfg), run_dir)
    for stale in remove_stale_temp_files(run_dir):
        say(f"removed a temporary file left by an interrupted write: {stale}")
    return RunFolder(run_dir, marker, stack, options, resolved)


def check_same_task(saved: Any, given: Any, run_dir: Path) -> None:
    """Raise unless a resume names the task its run was trained on (``--task``; None: none).

    A run trained on a task is resumed on that task, and a run trained without ``--task`` is
    resumed without it: a run folder holds one env's training.

    Raises:
        ValueError: Naming ``--task``, the run folder and the run's own task.
    """
    if saved == given:
        return
    if saved is None:
        raise ValueError(
            f"--task {given}: {run_dir} was trained without --task; resume it without --task, "
            "or start a new run"
        )
    raise ValueError(
        f"--task {given}: {run_dir} was trained on task {saved}; resume it with --task {saved} "
        "(or without --task: a resume keeps the run's task), or start a new run"
    )


TENSORBOARD_NOTICE = (
    "TensorBoard is not installed: training runs write no TensorBoard logs (tb/); "
    'pip install "fdia-env[tensorboard]" adds them'
)


def tensorboard_installed() -> bool:
    """Whether the ``tensorboard`` package (the ``tensorboard`` extra) can be imported."""
    try:
        return importlib.util.find_spec("tensorboard") is not None
    except ValueError:  # in sys.modules without a spec
        return False


@functools.cache
def _notice_no_tensorboard() -> None:
    """Print :data:`TENSORBOARD_NOTICE` to stderr, once per process."""
    print(TENSORBOARD_NOTICE, file=sys.stderr)


def tensorboard(folder: Path, purge_from: int | None = None, stdout: bool = False) -> Any:
    """SB3 logger writing TensorBoard events to ``folder`` (and a table to stdout).

    Without the ``tensorboard`` extra the logger writes no events (and creates no ``folder``)
    and :data:`TENSORBOARD_NOTICE` is printed once; training, checkpoints, evaluations and
    scores are the same.

    Args:
        folder: TensorBoard folder.
        purge_from: On resume, the first step after the checkpoint: the new event file starts
            with a ``SessionLog.START`` there, and TensorBoard hides the earlier sessions'
            events from that step on (the resumed session logs them again), so the step
            ranges shown do not overlap.
        stdout: Also print SB3's statistics table.
    """
    from stable_baselines3.common.logger import (
        HumanOutputFormat,
        KVWriter,
        Logger,
        TensorBoardOutputFormat,
    )

    formats: list[KVWriter] = [HumanOutputFormat(sys.stdout)] if stdout else []
    if not tensorboard_installed():
        _notice_no_tensorboard()
        return Logger(folder=None, output_formats=formats)

    from torch.utils.tensorboard import SummaryWriter

    class _TensorBoard(TensorBoardOutputFormat):
        def __init__(self) -> None:  # SB3's __init__ takes no purge_step
            self.writer = SummaryWriter(log_dir=str(folder), purge_step=purge_from)
            self._is_closed = False

    Path(folder).mkdir(parents=True, exist_ok=True)
    return Logger(folder=str(folder), output_formats=[_TensorBoard(), *formats])
