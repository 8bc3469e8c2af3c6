"""The typed (incomplete-information) sensor game's native vector env on torch (CPU).

Nature's draw of the attacker's type comes from the device generator: equal to numpy in
distribution; with ``options`` forcing the type, equal to numpy to 1e-10 member by member.
"""

from __future__ import annotations

import numpy as np
import pytest

from fdia_env.envs.opponents import FixedMix
from fdia_env.vector.env import make_vector

torch = pytest.importorskip("torch")

MODULE = "fdia_env.sensor_game_v0"
KW = {
    "scenario": "ch4-position",
    "power": 25.0,
    "rounds": 2,
    "dynamics": "expected",
    "types": ("independent", "dependent"),
    "priors": (0.3, 0.7),
}


def _pure(n: int) -> FixedMix:
    probs = np.zeros(n)
    probs[(n - 1) // 2] = 1.0
    return FixedMix(probs)


@pytest.mark.parametrize("agent", ["attacker", "defender"])
@pytest.mark.parametrize("forced", ["independent", "dependent"])
def test_forced_type_equals_numpy(agent, forced):
    B = 6
    envs = {}
    for backend in ("numpy", "torch"):
        probe = make_vector(MODULE, 1, agent=agent, **KW)
        other = next(a for a in probe.parallel.possible_agents if a != agent)
        opp = _pure(int(probe.parallel.action_space(other).n))
        envs[backend] = make_vector(MODULE, B, agent=agent, opponent=opp, backend=backend, **KW)
    obs_n, info_n = envs["numpy"].reset(seed=4, options={"attacker_type": forced})
    obs_t, info_t = envs["torch"].reset(seed=4, options={"attacker_type": forced})
    np.testing.assert_allclose(obs_t.numpy(), obs_n, rtol=1e-6, atol=1e-7)
    if agent == "attacker":
        want = KW["types"].index(forced)
        np.testing.assert_array_equal(info_t["type"].numpy(), np.full(B, want))
        np.testing.assert_array_equal(info_n["type"], np.full(B, want))
    n = int(envs["numpy"].single_action_space.n)
    actions = np.arange(B) % n
    for t in range(KW["rounds"]):  # the forced episode, up to its end
        out_n = envs["numpy"].step(actions)
        out_t = envs["torch"].step(torch.as_tensor(actions))
        np.testing.assert_allclose(out_t[1].numpy(), out_n[1], rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(out_t[0].numpy(), out_n[0], rtol=1e-5, atol=1e-6)
        np.testing.assert_array_equal(out_t[2].numpy(), out_n[2], err_msg=f"step {t}")


def test_drawn_types_follow_the_prior_and_the_informed_features():
    # B = 4,000 draws of p(dependent) = 0.7 at reset and again at the autoreset: each frequency
    # within 5 standard errors; the informed attacker's last two features one-hot its type
    B, p = 4000, KW["priors"][1]
    env = make_vector(MODULE, B, backend="torch", **KW)
    obs, info = env.reset(seed=0)
    se = np.sqrt(p * (1 - p) / B)
    freqs = [info["type"].double().mean().item()]
    np.testing.assert_array_equal(obs[:, -2:].numpy(), np.eye(2)[info["type"].numpy()])
    actions = torch.zeros(B, dtype=torch.int64)
    for _ in range(KW["rounds"] + 1):  # through the NEXT_STEP autoreset (new draws)
        obs, _, _, _, info = env.step(actions)
    freqs.append(info["type"].double().mean().item())
    np.testing.assert_array_equal(obs[:, -2:].numpy(), np.eye(2)[info["type"].numpy()])
    for f in freqs:
        assert abs(f - p) < 5 * se, (freqs, p, se)


def test_forced_type_checked_on_torch():
    env = make_vector(MODULE, 2, backend="torch", **KW)
    with pytest.raises(ValueError, match="attacker_type must be one of"):
        env.reset(seed=0, options={"attacker_type": "nonsense"})
