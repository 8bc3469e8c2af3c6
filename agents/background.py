"""Jobs run in order on one background thread: a training run's evaluations and checkpoints.

torch-ppo hands its evaluations (of a snapshot of the policy) and its checkpoint writes to a
:class:`Background` and goes on training. One worker runs them first in, first out, so the
files are written in the order the run made them: an evaluation at step S is in
``evaluations.jsonl`` before the checkpoint at S is, and a run killed at any moment resumes
from a checkpoint whose evaluations are all on disk (those after it are dropped and done again,
as for a run that evaluates inline). At most ``max_pending`` jobs wait: a run that evaluates
faster than it trains waits for the oldest instead of piling snapshots up.

A job that fails stops the others: its exception is raised in the training thread by the next
:meth:`Background.submit` or by :meth:`Background.drain`, the same exception object, so a full
disk is reported as it would be inline.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from types import TracebackType
from typing import Any

from agents.options import check_int


class Background:
    """A first-in, first-out queue of jobs run by one worker thread.

    Args:
        name: The worker thread's name (shown by debuggers and ``threading.enumerate``).
        max_pending: Jobs that may wait or run at once (>= 1); :meth:`submit` waits for the
            oldest beyond it.

    Raises:
        ValueError: For ``max_pending`` below 1.
    """

    def __init__(self, name: str = "background", max_pending: int = 2) -> None:
        check_int("max_pending", max_pending, 1)
        self.max_pending = max_pending
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=name)
        self._pending: deque[Future] = deque()
        self._failed: BaseException | None = None

    def submit(self, job: Callable[..., Any], *args: Any) -> None:
        """Queue ``job(*args)`` after the jobs already queued.

        Raises:
            BaseException: The exception of an earlier job that failed (then nothing more runs).
        """
        self._collect()
        while len(self._pending) >= self.max_pending:
            self._wait_oldest()
        if self._failed is None:
            self._pending.append(self._pool.submit(self._guarded, job, args))
        self._raise()

    def drain(self) -> None:
        """Wait until every queued job has run.

        Raises:
            BaseException: The exception of the first job that failed.
        """
        while self._pending:
            self._wait_oldest()
        self._raise()

    def close(self, wait_only: bool = False) -> None:
        """Wait for the queued jobs and stop the worker.

        Args:
            wait_only: Do not raise a job's exception (the caller is already raising one).
        """
        try:
            if wait_only:
                while self._pending:
                    self._pending.popleft().exception()
            else:
                self.drain()
        finally:
            self._pool.shutdown(wait=True)

    def __enter__(self) -> Background:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close(wait_only=exc_type is not None)

    def _guarded(self, job: Callable[..., Any], args: tuple) -> Any:
        if self._failed is not None:  # a job before this one failed: skip the rest
            return None
        try:
            return job(*args)
        except BaseException as exc:
            self._failed = exc
            raise

    def _wait_oldest(self) -> None:
        self._pending.popleft().exception()  # waits; the failure is kept in _failed

    def _collect(self) -> None:
        while self._pending and self._pending[0].done():
            self._wait_oldest()

    def _raise(self) -> None:
        if self._failed is not None:
            raise self._failed
