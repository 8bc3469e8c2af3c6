"""The benchmark's leaderboard: train and score learners on the named tasks, render the page.

``fdia-leaderboard`` (``python -m experiments bench`` in a checkout; :mod:`agents.leaderboard.cli`)
trains each requested learner on each requested task for each seed
(:mod:`agents.leaderboard.run`), scores it with :func:`agents.bench.score.score_policy` and
writes JSON rows to the ``--out`` file (:mod:`agents.leaderboard.rows`: atomic writes, resume, a
failed run as a failed row); :mod:`agents.leaderboard.render` turns the rows, with each task's
stored references (random play, the heuristics, the certified optimum), into the leaderboard
page and one plot per task family, where ``--page`` and ``--figures`` say (by default beside
``--out``).
"""
