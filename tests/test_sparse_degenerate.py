"""Sparse solvers on degenerate inputs: sensors without information, duplicates, extreme scales.

Every sparse solver must terminate on every system :class:`LinearSystem` accepts, with finite
values, ``upper_bound >= optimum >= every heuristic``, and branch and bound equal to the
exhaustive optimum when it reports a proof.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from baselines.sparse import (
    branch_and_bound,
    dp,
    exhaustive,
    make_problem,
    sbs,
    sfs,
    sfs_ss,
    upper_bound,
)
from baselines.sparse.bound import information_groups, root_bound
from baselines.sparse.split import split_bound
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


# --- a precise sensor: the bounds' downdates must not cancel --------------------------------

# Two systems (2 states, 2 scalar sensors) with one sensor far more precise than the prior, so
# that ``1 − l_q`` and ``I − G_DD`` cancel: the split bound (first) and the smoother bound
# (second) fell to 117.89 and 1.58, below the optima 261.47 and 2.006 (dropping the precise
# sensor at the last step).
PRECISE = {
    "split": (
        [[-1.4308730228590871, -0.9365477163197146], [0.3939383568003809, -0.5240866279019979]],
        [[45.32780127154826, 3.04561741658692], [3.04561741658692, 152.30015994254902]],
        [[934.8081251522784, 325.2897317201215], [0.005282440588173495, 0.00809692384427378]],
        [0.001288115826518559, 1.6082937103247137],
        (2, 0),
        261.4742422279661,
    ),
    "smoother": (
        [[-0.26048783048713586, 1.160014078446246], [-0.42590500572331313, -0.985005179806492]],
        [[0.31035101476715066, 0.23418971265963234], [0.23418971265963234, 0.2593089216734299]],
        [[-0.013745563131781848, 0.011189103700947082], [-828.8793389393733, 146.2150465164347]],
        [0.2823280861604556, 0.001121122629741933],
        (2, 1),
        2.006137813051282,
    ),
}


def precise_system(name: str) -> LinearSystem:
    F, Q, H, R, _, _ = PRECISE[name]
    sensors = tuple(Sensor(H=np.array([h]), R=np.array([[r]])) for h, r in zip(H, R, strict=True))
    return LinearSystem(F=np.array(F), Q=np.array(Q), sensors=sensors)


def joseph_value(system: LinearSystem, attacked: set, horizon: int) -> float:
    """tr P[K+N|K+N] by the covariance-form (Joseph) update, one scalar sensor at a time."""
    P = make_problem(system, 0, horizon).P_start
    n = system.n
    for k in range(horizon):
        P = system.F @ P @ system.F.T + system.Q
        for i, s in enumerate(system.sensors):
            if (k, i) in attacked:
                continue
            h, r = s.H, s.R
            K = P @ h.T / (h @ P @ h.T + r)
            A = np.eye(n) - K @ h
            P = A @ P @ A.T + K @ r @ K.T
    return float(np.trace(P))


@pytest.mark.parametrize("name", sorted(PRECISE))
def test_bounds_hold_with_a_sensor_far_more_precise_than_the_prior(name):
    system = precise_system(name)
    *_, pair, value = PRECISE[name]
    assert joseph_value(system, {pair}, 3) == pytest.approx(value, rel=1e-6)  # independent
    optimum = exhaustive(system, 1, 3)
    assert optimum.attacks == (pair,) and optimum.value == pytest.approx(value, rel=1e-12)
    problem = make_problem(system, 1, 3)
    for bound in (upper_bound(system, 1, 3), split_bound(problem).bound, root_bound(problem)):
        assert bound >= value * (1 - 1e-12)
    result = branch_and_bound(system, 1, 3, time_limit=30)
    assert result.proved_optimal and result.value == pytest.approx(value, rel=1e-12)


# --- every solver on random degenerate systems ----------------------------------------------

RTOL = 1e-9  # rounding between the solvers' arithmetic and the reference recursion


def degenerate_system(seed: int) -> tuple[LinearSystem, int]:
    """A random small system with degenerate sensors and extreme (but consistent) scales.

    Q, H and R each carry a scale in 1e-8..1e8 (the units of the state and the measurements);
    each sensor's signal-to-noise ``s_H² s_Q / s_R`` lies in 1e-4..1e4, except that a sensor
    may be a zero row, a copy of the previous one (ties), or one with an R 1e8 times too large
    (information ~0). F is stable, so every such system is accepted. Returns (system, horizon).
    """
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 3))
    M = int(rng.integers(1, 4))
    horizon = int(rng.integers(1, 7 // M + 1))
    F = rng.normal(size=(n, n))
    F *= rng.uniform(0.3, 0.95) / max(np.abs(np.linalg.eigvals(F)).max(), 1e-9)
    s_q, s_h = 10.0 ** rng.uniform(-8, 8, size=2)
    A = rng.normal(size=(n, n))
    Q = s_q * (A @ A.T + 1e-3 * np.eye(n))
    sensors: list[Sensor] = []
    for _ in range(M):
        kind = rng.choice(["normal", "zero", "copy", "weak"], p=[0.55, 0.15, 0.15, 0.15])
        if kind == "copy" and sensors:
            sensors.append(sensors[-1])
            continue
        H = s_h * rng.normal(size=(1, n))
        snr = 10.0 ** (rng.uniform(-4, 4) if kind != "weak" else -8.0)
        R = np.array([[s_h**2 * s_q / snr]])
        sensors.append(Sensor(H=np.zeros((1, n)) if kind == "zero" else H, R=R))
    return LinearSystem(F=F, Q=Q, sensors=tuple(sensors)), horizon


@given(
    seed=st.integers(0, 2**32 - 1),
    budget_fraction=st.floats(0.0, 1.0),
    objective=st.sampled_from(["trace", "logdet"]),
)
@settings(max_examples=12, deadline=None)
def test_every_sparse_solver_terminates_and_agrees_on_degenerate_systems(
    seed, budget_fraction, objective
):
    system, horizon = degenerate_system(seed)
    budget = round(budget_fraction * system.M * horizon)
    args = (system, budget, horizon, objective)
    with alarm(60):
        optimum = exhaustive(*args).value
        heuristics = {f.__name__: f(*args).value for f in (sfs, sbs, sfs_ss, dp)}
        bound = upper_bound(*args)
        bnb = branch_and_bound(*args, time_limit=5)
    values = [optimum, bound, bnb.value, bnb.upper_bound, *heuristics.values()]
    assert all(np.isfinite(v) for v in values), values
    tol = RTOL * max(abs(optimum), 1.0 if objective == "logdet" else 1e-300)
    assert bound >= optimum - tol
    for name, value in heuristics.items():
        assert value <= optimum + tol, name
    if system.n == 1:  # DP is exact for a scalar state
        assert heuristics["dp"] == pytest.approx(optimum, rel=RTOL)
    assert bnb.value <= optimum + tol and bnb.upper_bound >= optimum - tol
    if bnb.proved_optimal:
        assert bnb.value == pytest.approx(optimum, rel=RTOL)


@pytest.mark.parametrize("scale", [1e-300, 1e-200, 1e200, 1e300])
def test_exhaustive_is_exact_for_a_two_state_system_at_extreme_scales(scale):
    # the 2x2 closed forms square the covariances' entries (a d - b^2 overflows at 1e155 and
    # underflows at 1e-162): the optimum still equals the best set by the Joseph recursion
    system = LinearSystem(
        F=np.array([[-0.22, -0.09], [-0.46, -0.36]]),
        Q=np.array([[1.7, -0.8], [-0.8, 0.8]]) * scale,
        sensors=(
            Sensor(H=np.array([[0.4, -0.4]]), R=np.array([[1.9 * scale]])),
            Sensor(H=np.array([[0.26, -1.41]]), R=np.array([[0.28 * scale]])),
        ),
        P0=np.eye(2) * scale,
    )
    pairs = [(k, i) for k in range(2) for i in range(2)]
    for budget in (1, 2):
        sets = list(itertools.combinations(pairs, budget))
        values = [joseph_value(system, set(s), 2) for s in sets]
        result = exhaustive(system, budget, 2)
        assert result.value == pytest.approx(max(values), rel=1e-12)
        assert result.attacks == sets[int(np.argmax(values))]
