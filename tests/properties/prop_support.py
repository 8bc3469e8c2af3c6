"""Shared machinery of the property-based suite (``tests/properties``).

The properties all have one shape: *either the call succeeds and its outputs are sane (finite,
PSD, inside their spaces), or it raises ``ValueError``/``TypeError`` whose message names one of
the parameters passed*. :func:`outcome` runs a call under a hard time and memory bound and sorts
the result into those two cases; anything else (another exception, a hang, a message naming no
parameter) fails the example, and hypothesis shrinks it to a minimal input.

Budgets: ``max_examples`` is given per test as ``examples(k)``, ``k`` scaled by the loaded
hypothesis profile (``tests/conftest.py``: ``ci`` is the default, ``dev`` runs 10x more), so the
whole suite stays inside the CI budget.
"""

from __future__ import annotations

import contextlib
import math
import resource
import signal
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import numpy as np
from gymnasium import spaces
from hypothesis import settings
from hypothesis import strategies as st

from fdia_env import scenarios

HARD_LIMIT_S = 10.0  # SIGALRM: a call still running after this long is a hang
MEMORY_HEADROOM = 2 * 2**30  # bytes of address space a single call may add
OBS_SLACK = 1e-5  # float32 round-off allowed outside an observation Box


def build_presets() -> None:
    """Build every preset once (called when this module is imported, before any property runs).

    The grid presets run pandapower on their first ``scenarios.get`` (seconds, more on a loaded
    machine) and are cached after; building them here keeps that one-off cost out of the
    per-example deadline and the hard time bound, which measure the call under test.
    """
    for name in scenarios.names():
        try:
            scenarios.get(name)
        except ImportError:  # the [grid] extra is not installed: those examples say so
            pass


build_presets()


def examples(k: int) -> int:
    """``k`` examples under the ``ci`` profile, scaled with the loaded profile's budget."""
    return max(1, k * settings().max_examples // 100)


def prop_settings(k: int, deadline_s: float = 5.0) -> settings:
    """Per-test settings: ``examples(k)`` examples, each under ``deadline_s`` seconds."""
    return settings(max_examples=examples(k), deadline=deadline_s * 1000.0)


class Hang(Exception):
    """A call ran past :data:`HARD_LIMIT_S` (raised from the SIGALRM handler)."""


def _vm_size() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 0  # pragma: no cover


@contextlib.contextmanager
def bounded(seconds: float = HARD_LIMIT_S) -> Iterator[None]:
    """Interrupt the block after ``seconds`` (``Hang``) and cap its extra address space.

    Hypothesis's ``deadline`` only reports a slow example *after* it returns; a hang (e.g. a
    ``warmup=10**9`` loop) would never return, so SIGALRM interrupts it here. The address-space
    limit turns a runaway allocation into a ``MemoryError`` instead of swapping the machine.
    """

    def on_alarm(signum: int, frame: Any) -> None:
        raise Hang(f"call still running after {seconds} s")

    previous = signal.signal(signal.SIGALRM, on_alarm)
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    limit = _vm_size() + MEMORY_HEADROOM
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def names_one_of(exc: BaseException, names: Iterable[str]) -> bool:
    """Whether the message of ``exc`` contains one of ``names`` literally."""
    text = str(exc)
    return any(name in text for name in names)


def outcome(call: Callable[[], Any], names: Iterable[str]) -> tuple[bool, Any]:
    """Run ``call`` bounded; ``(True, result)`` or ``(False, exc)`` for an accepted error.

    Raises:
        AssertionError: For a ``ValueError``/``TypeError`` whose message names none of
            ``names``; any other exception (``Hang`` included) propagates and fails the example.
    """
    names = list(names)
    try:
        with bounded():
            return True, call()
    except (ValueError, TypeError) as exc:
        if not names_one_of(exc, names):
            raise AssertionError(
                f"{type(exc).__name__} names none of the parameters {names}: {exc}"
            ) from exc
        return False, exc


# --- values ---------------------------------------------------------------------------------
EDGE_NUMBERS = (0, 1, -1, 2**63, 10**9, 1e12, 1e-12, -1e12, math.nan, math.inf, -math.inf)
WRONG_TYPES = ("x", None, 1.5, 1 + 2j, [1], {"a": 1}, b"x", True, np.nan)


def wrong_values() -> st.SearchStrategy[Any]:
    """Edge numbers and wrong types (``object()`` included: a fresh one per draw)."""
    return st.one_of(
        st.sampled_from(EDGE_NUMBERS),
        st.sampled_from(WRONG_TYPES),
        st.builds(object),
        st.sampled_from([(), [], {}, np.zeros(0), np.array("x")]),
    )


def mixed(valid: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    """Mostly valid values, the rest edge values or wrong types."""
    return st.one_of(valid, valid, wrong_values())


@st.composite
def kwargs_of(
    draw: Any,
    params: dict[str, st.SearchStrategy[Any]],
    required: tuple[str, ...] = (),
    wrong: bool = True,
) -> dict[str, Any]:
    """A random subset of ``params`` (always the ``required`` ones), values from :func:`mixed`.

    With ``wrong=False`` the values are drawn from the valid strategies only.
    """
    chosen = set(draw(st.lists(st.sampled_from(sorted(params)), unique=True)))
    chosen |= set(required)
    pick = mixed if wrong else (lambda strategy: strategy)
    return {name: draw(pick(params[name])) for name in sorted(chosen)}


@st.composite
def small_matrices(
    draw: Any, max_rows: int = 3, max_cols: int = 3, square: bool = False
) -> np.ndarray:
    """Small float matrices: random Gaussian entries, sometimes with NaN/inf/huge entries."""
    rows = draw(st.integers(1, max_rows))
    cols = rows if square else draw(st.integers(1, max_cols))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    A = rng.standard_normal((rows, cols)) * draw(st.sampled_from([1e-12, 1e-3, 1.0, 10.0, 1e12]))
    if draw(st.booleans()) and draw(st.booleans()):
        A.flat[draw(st.integers(0, A.size - 1))] = draw(st.sampled_from([np.nan, np.inf, 1e300]))
    return A


@st.composite
def pd_matrices(draw: Any, n: int | None = None, max_n: int = 3) -> np.ndarray:
    """Symmetric positive definite matrices with eigenvalues in [1e-3, 1e3]."""
    n = draw(st.integers(1, max_n)) if n is None else n
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    V, _ = np.linalg.qr(rng.standard_normal((n, n)))
    S = (V * 10.0 ** rng.uniform(-3, 3, n)) @ V.T
    return 0.5 * (S + S.T)


def matrix_values(n: int | None = None) -> st.SearchStrategy[np.ndarray]:
    """PD matrices (of size ``n`` when given) mixed with arbitrary small matrices."""
    return st.one_of(pd_matrices(n), small_matrices(), small_matrices(square=True))


# --- checks on outputs ------------------------------------------------------------------------
def assert_in_space(space: spaces.Space, value: Any, where: str = "observation") -> None:
    """``value`` is an element of ``space``, Box bounds allowing float32 round-off."""
    if isinstance(space, spaces.Dict):
        assert isinstance(value, dict) and set(value) == set(space.spaces), (where, value)
        for key, sub in space.spaces.items():
            assert_in_space(sub, value[key], f"{where}[{key!r}]")
        return
    if isinstance(space, spaces.Box):
        arr = np.asarray(value)
        assert arr.shape == space.shape, f"{where}: shape {arr.shape} != {space.shape}"
        assert arr.dtype == space.dtype, f"{where}: dtype {arr.dtype} != {space.dtype}"
        values = arr.astype(np.float64)
        assert np.all(np.isfinite(values)), f"{where} not finite: {arr}"
        low, high = space.low.astype(np.float64), space.high.astype(np.float64)
        slack = OBS_SLACK * np.maximum(1.0, np.abs(np.where(np.isfinite(low), low, 0.0)))
        assert np.all(values >= low - slack), f"{where} below {space}: {arr}"
        slack = OBS_SLACK * np.maximum(1.0, np.abs(np.where(np.isfinite(high), high, 0.0)))
        assert np.all(values <= high + slack), f"{where} above {space}: {arr}"
        return
    assert space.contains(value), f"{where} {value!r} not in {space}"


def assert_psd(P: Any, what: str = "P", rtol: float = 1e-8, atol: float = 1e-10) -> None:
    """``P`` (..., n, n) is finite, symmetric and PSD to ``max(rtol · scale, atol)``.

    The absolute floor ``atol`` is the one of ``fdia_env._validation.check_psd`` (tolerance
    ``1e-10 · max(1, scale)``): a matrix the project accepts as PSD input passes here too.
    """
    P = np.asarray(P, dtype=np.float64)
    assert np.all(np.isfinite(P)), f"{what} not finite: {P}"
    scale = max(float(np.abs(P).max()), 1e-300) if P.size else 1.0
    asym = float(np.abs(P - np.swapaxes(P, -1, -2)).max()) if P.size else 0.0
    tol = max(rtol * scale, atol)
    assert asym <= tol, f"{what} not symmetric (|P - P'| = {asym:.3g}): {P}"
    if P.size:
        lowest = float(np.linalg.eigvalsh(0.5 * (P + np.swapaxes(P, -1, -2))).min())
        assert lowest >= -tol, f"{what} not PSD (λ_min = {lowest:.3g}): {P}"


def assert_finite(value: Any, what: str) -> None:
    """Every number in ``value`` (a scalar or array) is finite."""
    arr = np.asarray(value, dtype=np.float64)
    assert np.all(np.isfinite(arr)), f"{what} not finite: {value}"


def assert_simplex(x: Any, what: str, atol: float = 1e-7) -> None:
    """``x`` is a probability vector: finite, >= 0 and summing to 1 (to ``atol``)."""
    x = np.asarray(x, dtype=np.float64)
    assert_finite(x, what)
    assert np.all(x >= -atol), f"{what} has negative entries: {x}"
    assert abs(float(x.sum()) - 1.0) <= atol * max(1, x.size), f"{what} sums to {x.sum()}: {x}"


def info_signature(info: dict[str, Any]) -> dict[str, tuple]:
    """Keys of an info dict with each value's shape (scalars: ``()``)."""
    return {key: np.shape(value) for key, value in info.items()}
