"""agents/torch_ppo.py: PPO with env, rollout buffer and policy on one torch device (CPU here).

The training runs are short (B = 256 members) and check scores against the analytic references
that agents.evaluate uses; the building blocks (masked sampling, log-probabilities, GAE, the Box
action map, save/load) are checked against independent computations.
"""

import json
import re
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py lives at the root

import train
from agents.evaluate import evaluate
from agents.registry import get
from agents.torch_ppo import (
    ActorCritic,
    PolicySpec,
    TorchPolicy,
    TorchPPOConfig,
    gae,
    load_policy,
    load_training_state,
    make_torch_env,
    save_policy,
    save_training_state,
    train_torch_ppo,
)

SPARSE = get("sparse_attack_v0")
# measured (seeds 0-3, B = 256, 60k steps, CPU): every run plays the EXS set, score 1.0000
SPARSE_THRESHOLD = 0.99


@pytest.fixture(scope="module")
def sparse_run():
    """A short torch-ppo run on ch4-position; over-budget actions raise in the env."""
    torch.set_num_threads(1)
    kwargs = SPARSE.env_kwargs("ch4-position", illegal_action="error")
    env = make_torch_env(SPARSE.gym_id, 256, "cpu", **kwargs)
    config = TorchPPOConfig(total_timesteps=60_000, num_envs=256)
    result = train_torch_ppo(env, config, seed=0)
    single = gym.make(SPARSE.gym_id, **kwargs)
    return result, single, SPARSE.reference_of(single)


def test_torch_ppo_reaches_the_exs_optimum_on_ch4_position(sparse_run):
    result, single, reference = sparse_run
    assert reference.name == "EXS"
    assert reference.value == pytest.approx(0.032786, rel=1e-4)
    ev = evaluate(result.policy, single, 5, 0, reference)
    assert ev.score >= SPARSE_THRESHOLD, ev.score
    assert result.timesteps == 20 * 256 * 12  # ceil(60,000 / 3,072) whole iterations
    # the training return rose from random play (~0.013) to near the optimum
    assert result.history[0]["mean_return"] < 0.6 * reference.value
    assert result.history[-1]["mean_return"] >= 0.98 * reference.value


def test_training_never_stepped_an_illegal_action(sparse_run):
    # illegal_action="error": an over-budget subset raises inside env.step, so finishing the
    # run proves every sampled action was legal; the episodes all ended (6 steps each)
    result, _, _ = sparse_run
    assert all(h["episodes"] == 256 * 2 for h in result.history)


def test_masked_sampling_gives_illegal_actions_probability_zero():
    torch.manual_seed(0)
    model = ActorCritic(PolicySpec(obs_dim=5, kind="discrete", n=8))
    x = torch.randn(4000, 5)
    mask = torch.rand(4000, 8) < 0.4
    mask[:, 0] = True  # at least one legal action per row (the no-attack action is)
    gen = torch.Generator().manual_seed(1)
    actions = model.sample(x, mask, gen)
    assert mask.gather(1, actions[:, None]).all()
    greedy = model.sample(x, mask, gen, deterministic=True)
    assert mask.gather(1, greedy[:, None]).all()
    # the log-probability and entropy are those of the softmax renormalised over legal actions
    logp, entropy = model.log_prob_entropy(x, actions, mask)
    logits = model.actor(x).double()
    probs = torch.where(mask, logits.exp(), 0.0)
    probs = probs / probs.sum(1, keepdim=True)
    expected_logp = probs.gather(1, actions[:, None]).squeeze(1).log()
    expected_entropy = -torch.where(mask, probs * probs.clamp_min(1e-300).log(), 0.0).sum(1)
    torch.testing.assert_close(logp.double(), expected_logp, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(entropy.double(), expected_entropy, rtol=1e-5, atol=1e-6)


def test_masked_draws_follow_the_renormalised_softmax():
    model = ActorCritic(PolicySpec(obs_dim=2, kind="discrete", n=4))
    with torch.no_grad():
        model.actor[-1].weight.zero_()
        model.actor[-1].bias.copy_(torch.tensor([0.0, 1.0, 2.0, 3.0]))
    n = 200_000
    mask = torch.tensor([True, False, True, True]).expand(n, 4)
    gen = torch.Generator().manual_seed(2)
    actions = model.sample(torch.zeros(n, 2), mask, gen)
    freq = torch.bincount(actions, minlength=4).double() / n
    p = torch.tensor([1.0, 0.0, np.e**2, np.e**3], dtype=torch.float64)
    p = p / p.sum()
    assert freq[1] == 0.0
    # 5 standard errors of a binomial proportion
    assert torch.all((freq - p).abs() <= 5 * torch.sqrt(p * (1 - p) / n) + 1e-12)


def test_gae_equals_the_discounted_sum_of_td_errors():
    rng = np.random.default_rng(0)
    T, B, gamma, lam = 7, 5, 0.9, 0.8
    r, v = rng.normal(size=(T, B)), rng.normal(size=(T, B))
    d = (rng.random((T, B)) < 0.3).astype(float)
    v_next_last = rng.normal(size=B)
    got = gae(*(torch.tensor(a) for a in (r, v, d, v_next_last)), gamma, lam).numpy()
    v_next = np.vstack([v[1:], v_next_last])
    delta = r + gamma * v_next * (1 - d) - v
    expected = np.zeros((T, B))
    for t in range(T):  # A_t = Σ_k (γλ)^k δ_{t+k}, stopped after the first episode end
        for b in range(B):
            acc, w = 0.0, 1.0
            for k in range(t, T):
                acc += w * delta[k, b]
                if d[k, b]:
                    break
                w *= gamma * lam
            expected[t, b] = acc
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)


def test_box_actions_are_clipped_and_mapped_to_the_space():
    spec = PolicySpec(obs_dim=3, kind="box", n=2, low=(-1.0, 0.0), high=(1.0, 10.0))
    model = ActorCritic(spec)
    a = torch.tensor([[-5.0, 5.0], [0.0, 0.0], [0.5, -0.5]])
    got = model.to_env(a)
    torch.testing.assert_close(got, torch.tensor([[-1.0, 10.0], [0.0, 5.0], [0.5, 2.5]]))


def test_covariance_attacker_reaches_the_trace_optimum():
    # Box actions: a Gaussian policy; measured 0.99975, 0.99987, 0.99968 of trace-optimal at 80k
    # steps with 4 steps per rollout (seeds 0, 1, 2; 12 steps per rollout, fewer updates: 0.980)
    torch.set_num_threads(1)
    entry = get("covariance_attack_v0")
    kwargs = entry.env_kwargs(None)
    env = make_torch_env(entry.gym_id, 256, "cpu", **kwargs)
    config = TorchPPOConfig(total_timesteps=80_000, num_envs=256, num_steps=4)
    result = train_torch_ppo(env, config, seed=0)
    single = gym.make(entry.gym_id, **kwargs)
    ev = evaluate(result.policy, single, 3, 0)
    assert ev.reference_name == "trace-optimal"
    assert ev.score >= 0.99, ev.score
    action, _ = result.policy.predict(np.zeros((4, 4), dtype=np.float32))
    assert action.shape == (4, 3) and action.dtype == np.float32
    assert np.all(np.abs(action) <= 1.0)


def test_same_seed_same_training(sparse_run):
    kwargs = SPARSE.env_kwargs("ch4-position")
    runs = []
    for _ in range(2):
        env = make_torch_env(SPARSE.gym_id, 32, "cpu", **kwargs)
        runs.append(train_torch_ppo(env, TorchPPOConfig(total_timesteps=1000, num_envs=32), 3))
    a, b = (r.policy.model.state_dict() for r in runs)
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert [h["mean_return"] for h in runs[0].history] == [
        h["mean_return"] for h in runs[1].history
    ]


def _tiny(iterations: int) -> TorchPPOConfig:
    return TorchPPOConfig(total_timesteps=iterations * 32 * 12, num_envs=32)


def test_a_stopped_run_resumes_from_its_training_state(tmp_path):
    kwargs = SPARSE.env_kwargs("ch4-position")
    saved = []
    env = make_torch_env(SPARSE.gym_id, 32, "cpu", **kwargs)
    first = train_torch_ppo(
        env, _tiny(4), seed=1, stop=lambda: True, checkpoint=saved.append, checkpoint_freq=0
    )
    assert first.interrupted and first.timesteps == 384 and len(saved) == 1  # stop: checkpoint
    path = save_training_state(saved[0], tmp_path / "ckpt" / "state.json")
    state = load_training_state(path, tmp_path)
    assert (state.iteration, state.timesteps) == (1, 384)
    weights = first.policy.model.state_dict()
    assert all(torch.equal(state.model[k], weights[k]) for k in weights)
    assert state.optimizer["state"][0]["step"].item() == 4 * 4  # epochs x minibatches
    # nothing left to train: the resumed policy is the saved one, bit for bit
    env = make_torch_env(SPARSE.gym_id, 32, "cpu", **kwargs)
    same = train_torch_ppo(env, _tiny(1), seed=1, resume=state)
    assert same.timesteps == 384 and all(
        torch.equal(same.policy.model.state_dict()[k], weights[k]) for k in weights
    )
    # the continuation: counters, history and Adam's step count go on from the checkpoint,
    # checkpoints every 768 steps (after iterations 2 and 4, and the last one)
    ends = []
    runs = []
    for _ in range(2):
        env = make_torch_env(SPARSE.gym_id, 32, "cpu", **kwargs)
        runs.append(
            train_torch_ppo(
                env, _tiny(4), 1, resume=state, checkpoint=ends.append, checkpoint_freq=768
            )
        )
    rest = runs[0]
    assert rest.timesteps == 4 * 384 and not rest.interrupted
    assert [h["iteration"] for h in rest.history] == [1, 2, 3, 4]
    assert [e.iteration for e in ends[:2]] == [2, 4]
    assert ends[1].optimizer["state"][0]["step"].item() == 4 * 16
    assert rest.train_seconds >= state.seconds
    a, b = (r.policy.model.state_dict() for r in runs)  # a resume is deterministic
    assert all(torch.equal(a[k], b[k]) for k in a)
    # a state that does not fit the network is refused by name
    wrong = TorchPPOConfig(total_timesteps=768, num_envs=32, hidden=(8,))
    env = make_torch_env(SPARSE.gym_id, 32, "cpu", **kwargs)
    with pytest.raises(ValueError, match="resume state does not fit"):
        train_torch_ppo(env, wrong, 1, resume=state)
    pt = path.with_suffix(".pt")
    pt.write_bytes(pt.read_bytes()[:-1])
    with pytest.raises(ValueError, match="SHA-256"):
        load_training_state(path, tmp_path)


def test_saved_policy_loads_back_and_refuses_tampering(sparse_run, tmp_path):
    result = sparse_run[0]
    path = save_policy(result.policy, tmp_path / "model.json", num_timesteps=result.timesteps)
    loaded = load_policy(path, tmp_path)
    obs = np.random.default_rng(0).normal(size=(50, 5)).astype(np.float32)
    masks = np.random.default_rng(1).random((50, 8)) < 0.5
    masks[:, 0] = True
    got, _ = loaded.predict(obs, action_masks=masks)
    expected, _ = result.policy.predict(obs, action_masks=masks)
    np.testing.assert_array_equal(got, expected)
    assert json.loads(path.read_text())["num_timesteps"] == result.timesteps
    pt = path.with_suffix(".pt")
    pt.write_bytes(pt.read_bytes() + b"x")
    with pytest.raises(ValueError, match="SHA-256"):
        load_policy(path, tmp_path)
    with pytest.raises(ValueError, match="outside the run folder"):
        load_policy(path, tmp_path / "other")


def test_predict_rejects_a_wrong_observation_length(sparse_run):
    with pytest.raises(ValueError, match=r"observation must have shape \(5,\)"):
        sparse_run[0].policy.predict(np.zeros(4, dtype=np.float32))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"num_envs": 0}, r"num_envs must be in \[1, 16777216\], got 0"),
        ({"num_steps": 0}, "num_steps must be >= 1"),
        ({"learning_rate": -1.0}, "learning_rate must be > 0"),
        ({"gamma": 1.5}, r"gamma must be in \(0, 1\]"),
    ],
)
def test_config_rejects_bad_values(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TorchPPOConfig(**kwargs)


def test_training_rejects_a_negative_checkpoint_freq():
    env = make_torch_env(SPARSE.gym_id, 4, "cpu", **SPARSE.env_kwargs("ch4-position"))
    with pytest.raises(ValueError, match="checkpoint_freq must be >= 0"):
        train_torch_ppo(env, TorchPPOConfig(num_envs=4), checkpoint_freq=-1)


def test_training_rejects_a_numpy_env():
    env = gym.make_vec(SPARSE.gym_id, num_envs=4, vectorization_mode="vector_entry_point")
    with pytest.raises(ValueError, match="torch vector env"):
        train_torch_ppo(env, TorchPPOConfig(num_envs=4))


# ---------------------------------------------------------------------------- train.py


def test_cli_trains_and_writes_scores(tmp_path, capsys):
    run = train.main(
        [
            "attacker", "--algo", "torch-ppo", "--device", "cpu", "--num-envs", "256",
            "--total-timesteps", "60000", "--final-eval-episodes", "3", "--eval-episodes", "2",
            "--eval-freq", "30000", "--runs-root", str(tmp_path / "runs"),
        ]
    )  # fmt: skip
    assert run.run_dir.name.startswith("sparse_attack_v2-torch-ppo-s0-")
    for name in ("config.json", "scores.json", "model.json", "model.pt", "evaluations.jsonl"):
        assert (run.run_dir / name).is_file(), name
    scores = json.loads((run.run_dir / "scores.json").read_text())
    assert scores["num_envs"] == 256 and scores["device"] == "cpu"
    assert scores["num_timesteps"] == 61_440
    rows = scores["evaluations"]
    assert set(rows) == {"learned (torch-ppo)", "EXS", "random"}
    assert rows["learned (torch-ppo)"]["score"] >= SPARSE_THRESHOLD
    assert rows["EXS"]["score"] == pytest.approx(1.0, rel=1e-12)
    config = json.loads((run.run_dir / "config.json").read_text())["resolved"]
    assert config["algo"] == "torch-ppo" and config["hyperparameters"]["n_steps"] == 12
    history = [json.loads(line) for line in (run.run_dir / "evaluations.jsonl").open()]
    assert [h["timesteps"] for h in history] == [30_720, 61_440]
    out = capsys.readouterr().out
    assert "learned (torch-ppo)" in out and "reference (EXS)" in out
    loaded = load_policy(run.run_dir / "model.json", run.run_dir)
    assert isinstance(loaded, TorchPolicy)


def test_cli_resumes_a_stopped_run(tmp_path, monkeypatch):
    import agents.torch_ppo_train as runner

    argv = ["attacker", "--algo", "torch-ppo", "--device", "cpu", "--num-envs", "32",
            "--total-timesteps", "1536", "--final-eval-episodes", "2", "--eval-episodes", "2",
            "--eval-freq", "768", "--runs-root", str(tmp_path / "runs")]  # fmt: skip
    real = runner.train_torch_ppo

    def stopped_after_one(*args, **kwargs):  # as if SIGINT came during the first iteration
        return real(*args, **{**kwargs, "stop": lambda: True})

    monkeypatch.setattr(runner, "train_torch_ppo", stopped_after_one)
    first = train.main(argv)
    assert first.timesteps == 384 and not first.resumed
    state = json.loads((first.run_dir / "checkpoints" / "state.json").read_text())
    assert (state["iteration"], state["timesteps"]) == (1, 384)
    monkeypatch.setattr(runner, "train_torch_ppo", real)
    with pytest.raises(ValueError, match=r"options differ.*num-envs: saved 32, given 64"):
        train.main([*argv[:-2], "--num-envs", "64", "--resume", *argv[-2:]])
    # the saved options are the defaults of a resume: --run-dir alone continues it
    more = train.main(["attacker", "--resume", "--run-dir", str(first.run_dir)])
    assert more.run_dir == first.run_dir and more.resumed
    assert more.timesteps == 1536
    history = [json.loads(line) for line in (more.run_dir / "evaluations.jsonl").open()]
    assert [h["timesteps"] for h in history] == [384, 768, 1536]
    scores = json.loads((more.run_dir / "scores.json").read_text())
    assert scores["num_timesteps"] == 1536


@pytest.mark.parametrize(
    ("args", "message"),
    [  # options checked while parsing: status 2, the message on stderr (tyro's box)
        (["--device", "tpu"], r"device \(--device\) must be cpu, cuda"),
        (["--num-envs", "0"], r"num_envs \(--num-envs\) must be in \[1, 16777216\], got 0"),
        (["--n-steps", "0"], r"n_steps \(--n-steps\) must be >= 1"),
    ],
)
def test_cli_rejects_bad_options_naming_the_flag(tmp_path, capsys, args, message):
    argv = ["attacker", "--algo", "torch-ppo", *args, "--runs-root", str(tmp_path / "runs")]
    with pytest.raises(SystemExit) as exc:
        train.main(argv)
    assert exc.value.code == 2
    err = " ".join(capsys.readouterr().err.replace("│", " ").split())
    assert re.search(message, err), err
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [  # checked by the torch-ppo run before anything is written: ValueError (train.py: status 2)
        (["--batch-size", "64"], "batch_size does not apply to torch-ppo"),
        (["--resume"], "nothing to resume: no run folder"),
        (["--backend", "rllib"], "--algo torch-ppo runs in this process"),
    ],
)
def test_cli_rejects_options_torch_ppo_does_not_take(tmp_path, args, message):
    argv = ["attacker", "--algo", "torch-ppo", *args, "--runs-root", str(tmp_path / "runs")]
    with pytest.raises(ValueError, match=message):
        train.main(argv)
    assert not (tmp_path / "runs").exists()


def test_cli_num_envs_only_with_torch_ppo(tmp_path):
    with pytest.raises(ValueError, match="--num-envs applies to --algo torch-ppo and MaskablePPO"):
        train.main(["attacker", "--algo", "PPO", "--num-envs", "8"])


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a GPU")
def test_cli_cuda_without_a_gpu_names_the_device_flag(tmp_path):
    argv = ["attacker", "--algo", "torch-ppo", "--device", "cuda"]
    with pytest.raises(ValueError, match=r"device \(--device\): 'cuda' asked for but CUDA"):
        train.main([*argv, "--runs-root", str(tmp_path / "runs")])
