"""Agents: stable-baselines3 training, self-play and scoring against the analytic optima.

- :mod:`agents.config`: hyperparameters and run settings (dataclasses, per-algorithm defaults);
- :mod:`agents.seeding`: :func:`~agents.seeding.seed_everything`;
- :mod:`agents.registry`: the trainable envs, their scenarios, algorithms and references;
- :mod:`agents.evaluate`: :func:`~agents.evaluate.evaluate`, the one evaluation loop;
- :mod:`agents.algos`: the SB3 algorithms and :func:`~agents.algos.build_model`;
- :mod:`agents.checkpoint`: checkpoints as tensors and JSON (nothing unpickled unless trusted),
  paths confined to the run folder;
- :mod:`agents.interrupt`: graceful SIGINT/SIGTERM (stop, save, exit 130/143);
- :mod:`agents.training`: option checks, TensorBoard, atomic checkpoints, resume;
- :mod:`agents.selfplay`: iterated best response, fictitious self-play and PSRO;
- :mod:`agents.runs`, :mod:`agents.plots`: run folders and learning curves;
- :mod:`agents.demo`: ``make demo``;
- :mod:`agents.rllib`: Ray RLlib training, self-play and Ray Tune sweeps (``--backend rllib``,
  ``train.py sweep``; ray is imported only there, from the ``fdia-env[rllib]`` extra).

``train.py`` at the repository root is the command line over these.
"""
