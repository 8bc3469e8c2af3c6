"""The one options-validation module of agents: every check names the option and the range."""

import math

import numpy as np
import pytest

from agents.config import Hyperparameters, RunSettings
from agents.options import check_choice, check_int, check_number, check_real, flag
from agents.torch_ppo import TorchPPOConfig


def test_integers_in_range_pass_and_come_back_as_int():
    assert check_int("n", np.int64(3), 1) == 3 and type(check_int("n", np.int64(3), 1)) is int
    assert check_int("n", 8, 1, 8) == 8


@pytest.mark.parametrize(
    ("value", "error", "message"),
    [
        (True, TypeError, r"^n must be a number in \[1, 8\], got True$"),
        (2.0, TypeError, r"^n must be an integer in \[1, 8\], got 2.0$"),
        ("2", TypeError, r"^n must be a number in \[1, 8\], got '2'$"),
        (0, ValueError, r"^n must be in \[1, 8\], got 0$"),
        (9, ValueError, r"^n must be in \[1, 8\], got 9$"),
    ],
)
def test_bad_integers_name_the_option_and_the_range(value, error, message):
    with pytest.raises(error, match=message):
        check_int("n", value, 1, 8)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 0.0])
def test_reals_must_be_finite_and_allowed(value):
    with pytest.raises(ValueError, match=r"^lr must be > 0, got"):
        check_real("lr", value, lambda v: v > 0, "> 0")
    assert check_real("lr", np.float32(0.5), lambda v: v > 0, "> 0") == 0.5


def test_train_py_options_are_named_with_their_flag():
    assert flag("learning_rate") == "learning_rate (--learning-rate)"
    with pytest.raises(ValueError, match=r"^gamma \(--gamma\) must be in \(0, 1\], got 2$"):
        check_number("gamma", 2, float, lambda v: 0 < v <= 1, "in (0, 1]")
    with pytest.raises(ValueError, match=r"^backend \(--backend\) must be one of sb3, rllib"):
        check_choice("backend", 3, ("sb3", "rllib"))


def test_every_config_uses_the_same_checks():
    # train.py's options, torch-ppo's config and the run settings give the same message form
    with pytest.raises(ValueError, match=r"^learning_rate \(--learning-rate\) must be > 0"):
        Hyperparameters(learning_rate=-1.0)
    with pytest.raises(ValueError, match=r"^learning_rate must be > 0, got -1.0$"):
        TorchPPOConfig(learning_rate=-1.0)
    with pytest.raises(TypeError, match=r"^num_envs must be an integer in \[1, 16777216\]"):
        TorchPPOConfig(num_envs=2.5)
    with pytest.raises(ValueError, match=r"^num_env_runners \(--num-env-runners\) must be >= 0"):
        RunSettings(num_env_runners=-1)
