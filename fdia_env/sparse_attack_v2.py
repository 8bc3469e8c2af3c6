"""``sparse_attack_v2``: sparse sensor-time attacks, the plan built first by default.

The environment, its options and every action format are those of
:mod:`fdia_env.sparse_attack_v1` (read :mod:`fdia_env.sparse_attack_v0` for the dynamics,
observations and rewards); only the default decision order of the sequential format changes.
With ``action="auto"`` (the default) a system of more than 16 sensors (the power-grid presets:
34 to 304 meters) gets the sequential, masked format, and its decisions now come in the
plan-first order (``order="plan"``): the attacker first picks (sensor, window step) pairs of the
whole horizon, ``Discrete(N·M + 1)`` (action ``1 + k·M + j - 1`` = sensor j at window step
k + 1, 0 = stop), under a mask that forbids a pair already in the plan and every pair once the
plan uses the budget; then the plan plays out. v1's time-major order (each window step's set,
in the filter's order) does not learn on the grid presets: an untrained masked policy spends
the budget in the first window steps, while the optima attack late (docs/guide/sparse.md,
decision order). It stays by name (``order="time"``), as do the other formats
(``action="multibinary"``, ``"bitmask"``, ``"single"``). Up to 16 sensors ``"auto"`` is still the
``Discrete(2**M)`` bitmask (no decision order).

Gymnasium id ``fdia_env/SparseAttack-v2`` (with its native vector env:
``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``);
``fdia_env/SparseAttack-v1`` and ``-v0`` stay, unchanged, for results made with them.

## Action Space

``action="auto"`` (default): ``Discrete(N·M + 1)`` in the sequential format's plan-first order
above 16 sensors (an episode takes at most c + 1 decisions); ``Discrete(2**M)``, the bitmask,
up to 16. ``action="sequential"`` takes ``order="plan"`` (default), ``order="increasing"``
(the plan's pairs picked in increasing order) or ``order="time"`` (``Discrete(M + 1)``, v1's
default). The other formats by name, as in ``sparse_attack_v0``.

## Observation Space

As ``sparse_attack_v1``: ``Dict(observation=Box(float32), action_mask=Box(0, 1, (A,), int8))``;
in the plan-first order the ``Box`` ends with the N·M plan entries (step-major) and the budget
left after the plan's steps not yet played.

## Rewards

As ``sparse_attack_v0``; a pick pays 0 and the plan's window steps pay their rewards as they
play, so every attack set returns the same value in every format and order.

## Version History

- v2: the sequential format's default order is plan-first (``order="plan"``; v1:
  ``"time"``), so ``action="auto"`` above 16 sensors is the plan-first order. Everything else
  as v1.
- v1: ``action="auto"`` is the sequential format above 16 sensors (v0: ``MultiBinary(M)``);
  the sequential format's ``max_cycles`` counts decisions.
- v0: initial release. Infos with the same keys at reset and at every step, ``max_cycles``,
  ``render_mode="human"``.

## Example

>>> from fdia_env import sparse_attack_v2
>>> env = sparse_attack_v2.parallel_env(scenario="grid-ieee14")  # 34 meters, N = 6
>>> env.action_space("attacker"), env.order
(Discrete(205), 'plan')
>>> sparse_attack_v2.parallel_env(scenario="grid-ieee14", order="time").action_space("attacker")
Discrete(35)
>>> sparse_attack_v2.parallel_env(scenario="ch4-position").action_space("attacker")
Discrete(8)
"""

from __future__ import annotations

from fdia_env.envs.factory import aec_views
from fdia_env.sparse_attack_v1 import sequential_above_16

NAME = "sparse_attack_v2"

parallel_env = sequential_above_16(
    NAME,
    None,
    """The PettingZoo ``ParallelEnv``: ``sparse_attack_v1``'s, plan-first by default.

    Arguments as :func:`fdia_env.sparse_attack_v1.parallel_env`, except ``order``: None
    (default) is ``"plan"`` in the sequential format (``action="sequential"``, or ``"auto"``
    above 16 sensors with a budget of at least 1) and ``"time"`` (no order) in the others.
    """,
)
raw_env, env = aec_views(parallel_env)
