"""The RLlib options of train.py that need no Ray: validation and the missing-extra error."""

from __future__ import annotations

import pytest

from agents.config import SweepConfig


def test_backend_rllib_without_ray_names_the_extra(monkeypatch, capsys):
    import importlib.util

    import train

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util,
        "find_spec",
        lambda name, *a: None if name.split(".")[0] == "ray" else real(name, *a),
    )
    status = train.cli(["attacker", "--backend", "rllib"])
    err = capsys.readouterr().err
    assert status == 2
    assert "fdia-env[rllib]" in err and "--backend rllib" in err


def test_selfplay_method_on_sb3_backend_is_refused(capsys):
    import train

    assert train.cli(["game", "--method", "selfplay"]) == 2
    assert "needs --backend rllib" in capsys.readouterr().err


def test_run_settings_reject_bad_ray_options():
    from agents.config import RunSettings

    with pytest.raises(ValueError, match=r"num_env_runners \(--num-env-runners\) must be >= 0"):
        RunSettings(num_env_runners=-1)
    with pytest.raises(ValueError, match="backend"):
        RunSettings(backend="tf")
    with pytest.raises(ValueError, match="ray-address"):
        RunSettings(ray_address=" ")
    with pytest.raises(ValueError, match="seeds"):
        SweepConfig(seeds=())
