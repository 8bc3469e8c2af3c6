"""The benchmark's leaderboard: train and score learners on the named tasks, render the page.

``python -m experiments bench`` (:mod:`experiments.bench.cli`) trains each requested learner on
each requested task for each seed (:mod:`experiments.bench.run`), scores it with
:func:`agents.bench.score.score_policy` and writes JSON rows; :mod:`experiments.bench.render`
turns the rows, with each task's stored references (random play, the heuristics, the certified
optimum), into the leaderboard of docs/benchmark.md and one plot per task family.
"""
