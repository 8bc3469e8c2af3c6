"""Simulated tracking runs up to the attack time, to check the static reduction dynamically.

:func:`~baselines.detection.problem.tracking_problem` replaces the filter's past by the prior
``N(x̂[K|K−1], P[K|K−1])``. :func:`simulate_prediction` runs the actual system and Kalman filter
(``runs`` independent runs, batched) through the clean steps 1..K−1 and returns the true state at
K with the filter's prediction ``x̂[K|K−1]``; :func:`~baselines.detection.evaluate.monte_carlo`
with ``states=`` then scores the detectors on those runs.
"""

from __future__ import annotations

import numpy as np

from fdia_env._validation import check_int
from fdia_env.kalman import information_update, masked_gain, predict_cov, psd_sqrt, sampled_step
from fdia_env.scenarios import Scenario, resolve


def simulate_prediction(
    scenario: str | Scenario = "ch3-tracking", runs: int = 10_000, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """``(x[K], x̂[K|K−1])``, each (runs, n), from simulated clean runs of the scenario.

    ``x[0] ~ N(x0, P0)``, ``x̂[0|0] = x0``, ``P[0|0] = P0``; steps 1..K−1 use every sensor with
    the optimal gains; the state and the filter are then propagated once more to K.
    """
    sc = resolve(scenario)
    if sc.attack_step is None:
        raise ValueError(f"scenario {sc.name!r} has no attack_step")
    runs = check_int("runs", runs, minimum=1)
    system = sc.system
    rng = np.random.default_rng(seed)
    q_factor, r_factor = psd_sqrt(system.Q), np.linalg.cholesky(system.R)
    x_hat = np.broadcast_to(system.x0, (runs, system.n)).copy()
    x = x_hat + rng.standard_normal((runs, system.n)) @ psd_sqrt(system.P0).T
    P = np.array(system.P0)
    for _ in range(sc.attack_step - 1):
        P = information_update(predict_cov(P, system.F, system.Q), system.J)
        W = masked_gain(P, system)
        x, x_hat, _, _ = sampled_step(
            rng, system, x, x_hat, W, Q_factor=q_factor, R_factor=r_factor
        )
    x_next = x @ system.F.T + system.Gu + rng.standard_normal((runs, system.n)) @ q_factor.T
    return x_next, x_hat @ system.F.T + system.Gu
