"""Kalman core: pure functions with leading batch dimensions."""

from fdia_env.kalman.filter import (
    covariance_update,
    information_update,
    joseph_update,
    masked_gain,
    predict,
    predict_cov,
    subset_update,
    update_mean,
)
from fdia_env.kalman.linalg import (
    inv2,
    logdet,
    objective,
    psd_sqrt,
    spd_inv,
    spd_inv_sum,
    sym,
    trace,
)
from fdia_env.kalman.sampled import draw, sampled_step
from fdia_env.kalman.steady import steady_state, steady_state_iterate
from fdia_env.kalman.unaware import actual_covariance_step, extra_mse, transition_matrices

__all__ = [
    "actual_covariance_step",
    "covariance_update",
    "draw",
    "extra_mse",
    "information_update",
    "inv2",
    "joseph_update",
    "logdet",
    "masked_gain",
    "objective",
    "predict",
    "predict_cov",
    "psd_sqrt",
    "sampled_step",
    "spd_inv",
    "spd_inv_sum",
    "steady_state",
    "steady_state_iterate",
    "subset_update",
    "sym",
    "trace",
    "transition_matrices",
    "update_mean",
]
