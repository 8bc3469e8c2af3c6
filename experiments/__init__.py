"""Experiment drivers beside the library: the result tables and the literature reproduction.

Nothing here is installed with ``fdia-env``; run it from a checkout of the repository:

- ``python -m experiments results <table> [--quick] [--seed S] [--out DIR]``
  (:mod:`experiments.results`): the learned-against-analytic result tables;
- ``python -m experiments reproduce <chapter> [--quick] [--output FILE]``
  (:mod:`experiments.reproduce`): the literature's tables and figures, written into
  ``docs/reproduction.md`` by default.

The drivers import the library (``fdia_env``, ``baselines``, ``agents``); the library never
imports them.
"""
