"""Sparse solvers on degenerate inputs: sensors without information, duplicates, extreme scales.

Every sparse solver must terminate on every system :class:`LinearSystem` accepts, with finite
values, ``upper_bound >= optimum >= every heuristic``, and branch and bound equal to the
exhaustive optimum when it reports a proof.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from baselines.sparse import (
    exhaustive,
)
from baselines.sparse.bound import information_groups
from fdia_env.systems import LinearSystem, Sensor

ROOT = Path(__file__).resolve().parents[1]
GUARD_S = 60  # the subprocess guard: far above the second the calls take


def zero_sensor_system() -> LinearSystem:
    """Two states, a useful scalar sensor and one whose measurement row is zero."""
    return LinearSystem(
        F=np.array([[0.9, 0.1], [0.0, 0.8]]),
        Q=0.1 * np.eye(2),
        sensors=(
            Sensor(H=np.array([[1.0, 0.5]]), R=np.array([[0.3]])),
            Sensor(H=np.zeros((1, 2)), R=np.array([[1.0]])),
        ),
    )


@contextlib.contextmanager
def alarm(seconds: int):
    """Fail (instead of hanging the suite) when the block runs longer than ``seconds``."""

    def expire(signum, frame):
        raise TimeoutError(f"did not return within {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def test_information_groups_put_a_sensor_without_information_in_the_first_group():
    J = zero_sensor_system().J
    with alarm(10):
        groups = information_groups(J)
    assert len(groups) == 1
    idx, w = groups[0]
    assert idx.tolist() == [0, 1]
    assert w[0] == pytest.approx(np.trace(J[0]), rel=1e-15) and w[1] == 0.0


_CHILD = """
import json, sys
import numpy as np
from baselines.sparse import branch_and_bound, upper_bound
sys.path.insert(0, {tests!r})
from test_sparse_degenerate import zero_sensor_system
s = zero_sensor_system()
out = []
for c in range(1, 7):
    r = branch_and_bound(s, c, 3, time_limit=2)
    out.append([upper_bound(s, c, 3), r.value, r.proved_optimal])
print(json.dumps(out))
"""


def test_a_sensor_without_information_does_not_hang_upper_bound_or_bnb():
    """Run in a subprocess with a guard: the calls must return (they once looped forever)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}
    code = _CHILD.format(tests=str(ROOT / "tests"))
    try:
        done = subprocess.run(
            [sys.executable, "-c", code],
            capture_output=True,
            text=True,
            timeout=GUARD_S,
            env=env,
            cwd=ROOT,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"upper_bound / branch_and_bound did not return within {GUARD_S} s")
    assert done.returncode == 0, done.stderr
    s = zero_sensor_system()
    for c, (bound, value, proved) in enumerate(json.loads(done.stdout), start=1):
        optimum = exhaustive(s, c, 3).value
        assert proved and value == pytest.approx(optimum, rel=1e-12)
        assert bound >= optimum * (1 - 1e-12)
    # the zero sensor never matters: c = 3 (every useful pair) is the most any attack reaches
    assert exhaustive(s, 6, 3).value == pytest.approx(exhaustive(s, 3, 3).value, rel=1e-14)
