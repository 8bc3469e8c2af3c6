"""``sparse_attack_v1``: sparse sensor-time attacks, sequential format by default above 16 sensors.

The environment, its options and every action format are those of
:mod:`fdia_env.sparse_attack_v0` (read its documentation); only the default format changes.
With ``action="auto"`` (the default) a system of more than 16 sensors (the power-grid presets:
34 to 304 meters) gets the sequential, masked format (``action="sequential"``:
``Discrete(M + 1)``, each window step's set built one sensor per decision, 0 = stop, an action
mask that forbids a chosen sensor and any over the budget left), which masked learners
(sb3-contrib's ``MaskablePPO``, RLlib's masked module, TorchRL's ``ActionMask``) take; v0 gives
``MultiBinary(M)`` there, which carries no budget mask and which its learners do not learn.
Up to 16 sensors ``"auto"`` is still the ``Discrete(2**M)`` bitmask. The old formats stay by
name (``action="multibinary"``, ``"bitmask"``, ``"single"``).

Gymnasium id ``fdia_env/SparseAttack-v1`` (its native vector env serves both defaults:
``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``); ``fdia_env/SparseAttack-v0``
and this package's ``sparse_attack_v0`` stay, unchanged, for results made with them.

## Action Space

``action="auto"`` (default): ``Discrete(M + 1)`` in the sequential format above 16 sensors
(action j adds sensor j to the window step's set, 0 stops and takes the window step; an episode
takes at most N + c decisions); ``Discrete(2**M)``, the bitmask, up to 16. The other formats by
name, as in ``sparse_attack_v0``. ``order="plan"`` (sequential format only; default
``"time"``) picks the (sensor, window step) pairs of the whole horizon first,
``Discrete(N·M + 1)``, then the plan plays out (see ``sparse_attack_v0``); ``train.py`` uses
it on the grid presets, where the time-major order does not learn.

## Observation Space

``Dict(observation=Box(float32), action_mask=Box(0, 1, (A,), int8))``: the features of
``sparse_attack_v0`` (steps left / N, log variance growth, correlations, budget left / c), and,
in the sequential format, M entries (1 = sensor in the set being built) and the budget left
after the set; the Gymnasium view returns the ``Box`` and puts the mask in
``info["action_mask"]`` and ``action_masks()``.

## Rewards

As ``sparse_attack_v0``: Φ (tr or log det of the error covariance, or the squared error in
sampled dynamics) at the last window step (``reward_mode="terminal"``), its increments
(``"shaped"``) or every step (``"per_step"``); in the sequential format a pick pays 0 and a stop
pays the window step(s) it plays, so every attack set returns the same value in every format.

## Version History

- v1: ``action="auto"`` is the sequential format above 16 sensors (v0: ``MultiBinary(M)``);
  the sequential format's ``max_cycles`` counts decisions. Everything else as v0.
- v0: initial release. Infos with the same keys at reset and at every step, ``max_cycles``,
  ``render_mode="human"``.

## Example

>>> from fdia_env import sparse_attack_v1
>>> env = sparse_attack_v1.parallel_env(scenario="grid-ieee14")  # 34 meters
>>> env.action_space("attacker")
Discrete(35)
>>> sparse_attack_v1.parallel_env(scenario="ch4-position").action_space("attacker")
Discrete(8)
"""

from __future__ import annotations

import inspect
from collections.abc import Callable

from fdia_env import sparse_attack_v0
from fdia_env._validation import check_choice, check_int
from fdia_env.attacks.sparse import ACTION_FORMATS, MAX_SENSORS
from fdia_env.envs.factory import aec_views, scenario_default
from fdia_env.envs.parallel import FdiaParallelEnv
from fdia_env.envs.sequential import SequentialSetEnv
from fdia_env.scenarios import resolve

NAME = "sparse_attack_v1"


def sequential_above_16(
    name: str, order: str | None, doc: str
) -> Callable[..., FdiaParallelEnv | SequentialSetEnv]:
    """``sparse_attack_v0.parallel_env`` with ``action="auto"`` sequential above 16 sensors.

    The factory of v1 and v2 (they differ by ``order``'s default only). The returned function
    has v0's signature (its parameters, read by ``inspect.signature``), ``order``'s default
    replaced.

    Args:
        name: The env's name (``metadata["name"]``).
        order: The default decision order of the sequential format; None: ``"plan"`` in the
            sequential format and ``"time"`` (no order) in the others.
        doc: The function's docstring.

    Returns:
        The module's ``parallel_env``.
    """
    base = inspect.signature(sparse_attack_v0.parallel_env)
    signature = base.replace(
        parameters=[
            p.replace(default=order, annotation="str | None" if order is None else p.annotation)
            if p.name == "order"
            else p
            for p in base.parameters.values()
        ]
    )

    def parallel_env(*args: object, **kwargs: object) -> FdiaParallelEnv | SequentialSetEnv:
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        kw = bound.arguments
        sc = kw["scenario"] = resolve(kw["scenario"])
        # the attack model checks the budget too; here first, before its truth is tested
        c = check_int("budget", scenario_default(sc, "budget", kw["budget"]), minimum=0)
        check_choice("action", kw["action"], (*ACTION_FORMATS, "sequential"))
        if kw["action"] == "auto" and sc.system.M > MAX_SENSORS and c:
            kw["action"] = "sequential"  # (a budget of 0 has no decision to make: v0's format)
        if kw["order"] is None:
            kw["order"] = "plan" if kw["action"] == "sequential" else "time"
        env = sparse_attack_v0.parallel_env(**kw)
        env.metadata["name"] = name
        if isinstance(env, SequentialSetEnv):
            env.inner.metadata["name"] = name
        return env

    parallel_env.__signature__ = signature  # type: ignore[attr-defined]
    parallel_env.__doc__ = doc
    return parallel_env


parallel_env = sequential_above_16(
    NAME,
    "time",
    """The PettingZoo ``ParallelEnv``: ``sparse_attack_v0``'s, sequential above 16 sensors.

    Arguments as :func:`fdia_env.sparse_attack_v0.parallel_env`; ``action="auto"`` resolves
    to ``"sequential"`` for more than 16 sensors and a budget of at least 1 (see the module
    docstring).
    """,
)
raw_env, env = aec_views(parallel_env)
