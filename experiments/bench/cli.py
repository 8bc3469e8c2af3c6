"""``python -m experiments bench``: :func:`agents.leaderboard.cli.main` under that name."""

from __future__ import annotations

from collections.abc import Sequence

from agents.leaderboard import cli


def main(argv: Sequence[str] | None = None) -> int:
    """Run the leaderboard runner (``fdia-leaderboard``) as ``python -m experiments bench``."""
    return cli.main(argv, prog="python -m experiments bench")
