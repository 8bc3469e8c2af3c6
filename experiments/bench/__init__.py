"""``python -m experiments bench``: the checkout's way to run ``fdia-leaderboard``.

The runner lives in the installed package :mod:`agents.leaderboard`; :mod:`experiments.bench.run`
and :mod:`experiments.bench.render` are its modules themselves (the same module objects).
"""
