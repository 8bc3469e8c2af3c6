"""Graceful Ctrl-C: the first SIGINT/SIGTERM stops training cleanly, a second one aborts.

:func:`stop_on_signals` installs handlers for SIGINT and SIGTERM (in the main thread only) and
restores the previous ones on exit, so training can be called as a library function. The first
signal only sets :attr:`StopRequest.signum`; :class:`StopTrainingCallback` makes SB3's ``learn``
return at its next environment step (an update in progress finishes first), and the caller
then writes its final checkpoint and scores. A second signal raises :class:`Aborted` (a
``KeyboardInterrupt``) at once. The conventional exit status is ``128 + signum``: 130 for
SIGINT, 143 for SIGTERM (:func:`exit_status`).
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from stable_baselines3.common.callbacks import BaseCallback

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Aborted(KeyboardInterrupt):
    """A second SIGINT/SIGTERM: stop at once, without a final checkpoint."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@dataclass
class StopRequest:
    """Set by the first signal: ``signum`` is the signal's number (None: not stopped)."""

    signum: int | None = None

    @property
    def requested(self) -> bool:
        """Whether a stop was asked for."""
        return self.signum is not None


def exit_status(signum: int) -> int:
    """The shell's status for a process stopped by ``signum``: ``128 + signum``."""
    return 128 + int(signum)


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


@contextmanager
def stop_on_signals(report: Callable[[str], None] | None = _stderr) -> Iterator[StopRequest]:
    """Handle SIGINT and SIGTERM while the block runs; restore the previous handlers after.

    Outside the main thread (where Python cannot install handlers) nothing is installed and the
    request is never set.

    Args:
        report: Called with one line when the first signal arrives (None: silent).
    """
    stop = StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    def handler(signum: int, frame: object) -> None:
        if stop.requested:
            raise Aborted(signum)
        stop.signum = signum
        if report is not None:
            report(
                f"\n{signal.Signals(signum).name}: stopping after the current step, then saving "
                "a checkpoint and the scores (press Ctrl-C again to abort at once)"
            )

    previous = {s: signal.getsignal(s) for s in SIGNALS}
    for s in SIGNALS:
        signal.signal(s, handler)
    try:
        yield stop
    finally:
        for s, old in previous.items():
            signal.signal(s, signal.SIG_DFL if old is None else old)


class Diverged(ValueError):
    """Training produced a non-finite loss, gradient or parameter; nothing after it was saved.

    Attributes:
        what: What became non-finite (``"the loss"``, ``"the gradient"``, a parameter's name).
        step: The env step at which it was found.
        last_good: The last checkpoint written before it (a description), or None.
    """

    def __init__(self, what: str, step: int, last_good: str | None = None) -> None:
        self.what, self.step, self.last_good = what, int(step), last_good
        where = (
            f"the last good checkpoint is {last_good}, which --resume continues (or start a "
            "new run with a smaller --learning-rate)"
            if last_good is not None
            else "no checkpoint was written before it"
        )
        super().__init__(
            f"training diverged at step {self.step}: {what} is not finite (NaN or infinity); "
            f"no checkpoint of the diverged weights was written; {where}"
        )


class StopTrainingCallback(BaseCallback):
    """Ends SB3's ``learn`` at the next environment step once ``stop`` is requested."""

    def __init__(self, stop: StopRequest) -> None:
        super().__init__()
        self.stop = stop

    def _on_step(self) -> bool:
        return not self.stop.requested
