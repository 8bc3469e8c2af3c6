"""The env modules' shared episode parameters (fdia_env.envs.factory.with_episode_parameters)."""

from __future__ import annotations

import inspect

import pytest

from fdia_env import covariance_attack_v0, detection_game_v0, fdia_v0, sparse_attack_v0
from fdia_env.envs.factory import EPISODE_PARAMETERS, with_episode_parameters

MODULES = (sparse_attack_v0, fdia_v0, covariance_attack_v0, detection_game_v0)


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[1])
def test_public_signature_lists_every_episode_parameter(module):
    params = inspect.signature(module.parallel_env).parameters
    assert not any(p.kind is p.VAR_KEYWORD for p in params.values())
    for name, (annotation, default) in EPISODE_PARAMETERS.items():
        assert params[name].default == default
        assert params[name].annotation == annotation
        assert params[name].kind is inspect.Parameter.POSITIONAL_OR_KEYWORD
    assert next(iter(params)) == "scenario" and "render_mode" in params


def test_positional_call_follows_the_public_order():
    # scenario, budget, horizon, objective: the fourth positional is the objective
    by_position = sparse_attack_v0.parallel_env("ch4-position", 5, 6, "logdet")
    by_name = sparse_attack_v0.parallel_env(
        scenario="ch4-position", budget=5, horizon=6, objective="logdet"
    )
    assert by_position.spec.horizon == by_name.spec.horizon == 6
    assert by_position.spec.objective == by_name.spec.objective == "logdet"
    with pytest.raises(TypeError, match="unexpected keyword argument 'budgett'"):
        sparse_attack_v0.parallel_env(budgett=5)
    with pytest.raises(TypeError, match="multiple values for argument 'horizon'"):
        sparse_attack_v0.parallel_env("ch4-position", 5, 6, horizon=7)


def test_order_must_name_every_parameter_once():
    def parallel_env(scenario: str = "x", **episode: object) -> None:
        """A module's factory."""

    with pytest.raises(TypeError, match="order must list"):
        with_episode_parameters("scenario", "horizon")(parallel_env)
    decorated = with_episode_parameters("scenario", *EPISODE_PARAMETERS)(parallel_env)
    assert list(inspect.signature(decorated).parameters) == ["scenario", *EPISODE_PARAMETERS]
