"""The payoff matrix in the forms nashpy and OpenSpiel take.

Both libraries have each player *maximise* its own utility; here the defender (row player)
minimises L, so its utility is ``−L`` and the attacker's is ``L``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

from baselines.game.lp import as_payoff
from fdia_env.attacks.subsets import subset_name, subsets


def action_names(count: int) -> list[str]:
    """``z1, z2, ..., z1z2...`` when ``count = 2^M − 1`` for some M ≤ 20, else ``a0, a1, ...``."""
    M = count.bit_length()
    if count == 2**M - 1 and M <= 20:
        return [subset_name(s) for s in subsets(M)]
    return [f"a{j}" for j in range(count)]


def to_nashpy(L: Any) -> Any:
    """A ``nashpy.Game`` with row utility ``−L`` and column utility ``L`` (zero-sum).

    Use its ``linear_program()`` (or ``lemke_howson``) for a cross-check; support enumeration
    finds no equilibrium on float-valued games (a ``prob >= 0`` check rejects −1e-17).

    Raises:
        ValueError: If ``L`` is not a finite, non-empty 2-D matrix.
        ImportError: If nashpy is not installed (it is in the ``dev`` extra).
    """
    import nashpy

    L = as_payoff(L)
    return nashpy.Game(-L, L)


class OpenSpielMatrixArgs(NamedTuple):
    """Positional arguments of ``pyspiel.create_matrix_game``, in its order.

    ``pyspiel.create_matrix_game(*to_openspiel_matrix(L))`` builds the game (OpenSpiel is not a
    dependency; this only prepares the arguments).

    Attributes:
        short_name: Game short name.
        long_name: Game long name.
        row_action_names: The defender's action names (subset names for a full game).
        col_action_names: The attacker's action names.
        row_utilities: Row player (defender) utilities, ``−L`` as nested lists.
        col_utilities: Column player (attacker) utilities, ``L`` as nested lists.
    """

    short_name: str
    long_name: str
    row_action_names: list[str]
    col_action_names: list[str]
    row_utilities: list[list[float]]
    col_utilities: list[list[float]]


def to_openspiel_matrix(
    L: Any,
    short_name: str = "fdia_sensor_game",
    long_name: str = "FDIA sensor-selection game",
    row_action_names: Sequence[str] | None = None,
    col_action_names: Sequence[str] | None = None,
) -> OpenSpielMatrixArgs:
    """The arguments ``pyspiel.create_matrix_game`` takes for the zero-sum game ``L``.

    Args:
        L: (m, n) payoff to the attacker (the defender minimises it).
        short_name: OpenSpiel short name.
        long_name: OpenSpiel long name.
        row_action_names: m names (default subset names ``z1, ...`` when m = 2^M − 1).
        col_action_names: n names (same default).

    Returns:
        :class:`OpenSpielMatrixArgs`: short and long name, row and column action names, row
        utilities ``−L`` and column utilities ``L`` (OpenSpiel players maximise).

    Raises:
        ValueError: For a bad matrix or a name list of the wrong length.

    Example:
        >>> args = to_openspiel_matrix([[1.0, 2.0], [3.0, 4.0]])
        >>> args.row_action_names, args.row_utilities[0], args.col_utilities[0]
        (['a0', 'a1'], [-1.0, -2.0], [1.0, 2.0])
    """
    L = as_payoff(L)
    m, n = L.shape
    rows = list(row_action_names) if row_action_names is not None else action_names(m)
    cols = list(col_action_names) if col_action_names is not None else action_names(n)
    if len(rows) != m:
        raise ValueError(f"row_action_names must have {m} names, got {len(rows)}")
    if len(cols) != n:
        raise ValueError(f"col_action_names must have {n} names, got {len(cols)}")
    return OpenSpielMatrixArgs(short_name, long_name, rows, cols, (-L).tolist(), L.tolist())
