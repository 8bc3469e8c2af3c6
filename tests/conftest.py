"""Small shared helpers of the tests (the Kalman core's, and the vector envs' comparisons).

Imported by the test modules as ``from conftest import ...`` (pytest puts ``tests/`` on the path).
"""

from __future__ import annotations

import contextlib
import io
import itertools
import os
import shlex
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st

from fdia_env.systems import LinearSystem, Sensor

# Hypothesis profiles, picked by HYPOTHESIS_PROFILE (default "ci"). "ci": the same examples on
# every run (derandomize), no example database; "dev": 10x the examples of the property suite
# (tests/properties scales its per-test budgets by max_examples / 100), random, with a database.
settings.register_profile(
    "ci",
    derandomize=True,
    database=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile(
    "dev", max_examples=1000, suppress_health_check=[HealthCheck.too_slow], print_blob=True
)
settings.register_profile(  # find failures fast: no shrinking, every distinct bug reported
    "triage", parent=settings.get_profile("dev"), phases=[Phase.explicit, Phase.generate]
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


def all_masks(M: int) -> np.ndarray:
    """Every non-empty sensor subset as a (2^M − 1, M) boolean array, by size then lexicographic."""
    subsets = [c for r in range(1, M + 1) for c in itertools.combinations(range(M), r)]
    masks = np.zeros((len(subsets), M), dtype=bool)
    for row, subset in enumerate(subsets):
        masks[row, list(subset)] = True
    return masks


def random_psd(rng: np.random.Generator, n: int, rank: int | None = None, power: float = 1.0):
    """A random symmetric PSD (n, n) matrix of the given rank with trace ``power``."""
    A = rng.standard_normal((n, n if rank is None else rank))
    S = A @ A.T
    S = 0.5 * (S + S.T)
    return S * (power / np.trace(S)) if power else np.zeros((n, n))


def random_pd(rng: np.random.Generator, n: int, low: float = 0.1, high: float = 10.0):
    """A random symmetric PD matrix with eigenvalues drawn uniformly in [low, high]."""
    V, _ = np.linalg.qr(rng.standard_normal((n, n)))
    S = (V * rng.uniform(low, high, n)) @ V.T
    return 0.5 * (S + S.T)


def rel_err(a: np.ndarray, b: np.ndarray) -> float:
    """Largest entry-wise difference relative to the largest entry of ``b`` (at least 1e-300)."""
    a, b = np.asarray(a), np.asarray(b)
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


def random_system(seed: int, n: int, dims: list[int], q_rank: int, radius: float) -> LinearSystem:
    """A random system with ‖F‖₂ < ``radius``, a rank-``q_rank`` PSD Q and PD R blocks ``dims``.

    With ``q_rank`` 0 (Q = 0) F is scaled by ``0.99 / 1.19`` so that ‖F‖₂ < 0.99 for every
    ``radius <= 1.19``: an unstable mode without process noise is not stabilisable and
    :class:`LinearSystem` rejects it. A nonzero Q of random range and random H drive and see
    every unstable mode (the failing cases have probability zero), so every call builds.
    """
    rng = np.random.default_rng(seed)
    U, _ = np.linalg.qr(rng.standard_normal((n, n)))
    V, _ = np.linalg.qr(rng.standard_normal((n, n)))
    F = (U * rng.uniform(0.2, radius, n)) @ V.T  # singular values in [0.2, radius)
    if not q_rank:
        F *= 0.99 / 1.19
    Q = random_psd(rng, n, rank=q_rank, power=rng.uniform(0.01, 2.0) if q_rank else 0.0)
    sensors = tuple(
        Sensor(H=rng.standard_normal((d, n)), R=random_pd(rng, d, 0.1, 5.0), name=f"s{i}")
        for i, d in enumerate(dims)
    )
    return LinearSystem(F=F, Q=Q, sensors=sensors, P0=random_pd(rng, n, 0.1, 10.0))


@st.composite
def stable_systems(draw, max_n: int = 4, max_sensors: int = 4) -> LinearSystem:
    """Random systems (:func:`random_system`): ‖F‖₂ < 1.2, PSD Q, PD R blocks of size 1 or 2.

    Sizes are drawn by hypothesis; the entries come from a numpy Generator seeded by hypothesis,
    so failures shrink to a reproducible seed. Every draw is a system ``LinearSystem`` accepts.
    """
    n = draw(st.integers(1, max_n))
    dims = draw(st.lists(st.sampled_from([1, 2]), min_size=1, max_size=max_sensors))
    q_rank = draw(st.integers(0, n))
    radius = draw(st.floats(0.2, 1.19))
    return random_system(draw(st.integers(0, 2**32 - 1)), n, dims, q_rank, radius)


def assert_infos_equal(native, sync, where="", atol=1e-9, obs_atol=1e-6):
    """Gymnasium vector infos equal key by key: keys, dtypes, shapes and ``_key`` masks.

    Floats to ``rtol=1e-9`` and ``atol``, integers and bools exactly; the per-member
    ``final_obs`` (None or an observation, float32) to 1e-6 relative and ``obs_atol``.
    """
    assert sorted(native) == sorted(sync), f"{where}: keys {sorted(native)} != {sorted(sync)}"
    for key in sync:
        n, s = native[key], sync[key]
        if isinstance(s, dict):
            assert_infos_equal(n, s, f"{where}/{key}", atol, obs_atol)
        elif s.dtype == object:  # final_obs: None or the member's observation
            for a, b in zip(n, s, strict=True):
                assert (a is None) == (b is None), f"{where}/{key}"
                if b is not None:
                    np.testing.assert_allclose(a, b, rtol=1e-6, atol=obs_atol, err_msg=where)
        else:
            assert n.dtype == s.dtype, f"{where}/{key}: dtype {n.dtype} != {s.dtype}"
            assert n.shape == s.shape, f"{where}/{key}: shape {n.shape} != {s.shape}"
            if np.issubdtype(s.dtype, np.floating):
                np.testing.assert_allclose(n, s, rtol=1e-9, atol=atol, err_msg=f"{where}/{key}")
            else:
                np.testing.assert_array_equal(n, s, err_msg=f"{where}/{key}")


def attacker_return(env, policy, seed: int = 0) -> float:
    """Return of one episode of ``policy`` (SB3's ``predict``, deterministic) as the attacker
    of a parallel env without a defender, from ``reset(seed=seed)``."""
    obs, _ = env.reset(seed=seed)
    total = 0.0
    while env.agents:
        action, _ = policy.predict(obs["attacker"], deterministic=True)
        obs, rewards, *_ = env.step({"attacker": action})
        total += rewards["attacker"]
    return total


def printed_by(code: str, name: str) -> str:
    """What a documented Python block prints when run (in a fresh namespace).

    Warnings are errors: a page's example that makes Gymnasium, PettingZoo or numpy warn (an
    out-of-date env id, a deprecated call) fails.
    """
    out = io.StringIO()
    with contextlib.redirect_stdout(out), warnings.catch_warnings():
        warnings.simplefilter("error")
        exec(compile(code, name, "exec"), {})
    return out.getvalue()


def command_output(command: str, cwd: os.PathLike | str, timeout: float = 600) -> str:
    """What a documented shell command prints (stdout), run from the checkout's code.

    ``command`` is one ``python ...`` line of a page (``python train.py ...``, ``python -m
    agents.bench ...``): it runs with this interpreter and ``-W error`` (a warning fails it),
    the checkout's root first on ``PYTHONPATH``, one BLAS thread, in ``cwd`` (where a run
    folder it writes goes). A nonzero exit status fails with the end of its stderr.
    """
    args = shlex.split(command.replace("\\\n", " "))  # a line continued with a backslash
    if args[0] != "python":
        raise ValueError(f"command must start with 'python', got {command!r}")
    root = Path(__file__).resolve().parent.parent
    if len(args) > 1 and args[1].endswith(".py"):
        args[1] = str(root / args[1])  # a script of the checkout (train.py)
    path = os.pathsep.join(p for p in (str(root), os.environ.get("PYTHONPATH")) if p)
    env = {**os.environ, "PYTHONPATH": path, "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run(
        [sys.executable, "-W", "error", *args[1:]],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    assert done.returncode == 0, f"{command} exited {done.returncode}:\n{done.stderr[-3000:]}"
    return done.stdout
