"""The benchmark's commands: reference values of the tasks and scoring agents on them.

``python -m agents.bench verify [--task T] [--cheap]`` recomputes the stored references of
:mod:`fdia_env.tasks` and compares them; ``compute`` writes them; ``score`` scores an agent on a
task (:mod:`agents.bench.score`).
"""
