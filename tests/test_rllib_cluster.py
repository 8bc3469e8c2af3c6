"""``--ray-address`` against a real Ray cluster: ``ray start --head`` in a subprocess.

The head (2 CPUs, free ports, its own temp dir and auth token) runs for this module only and is
stopped by SIGTERM to its ``ray start --block`` process (which shuts down every process it
started) even when a test fails. Needs the fdia-env[rllib] extra and the ``ray`` executable
beside the Python running the tests (skipped otherwise).
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

pytest.importorskip("ray.rllib", reason="needs the fdia-env[rllib] extra")

ROOT = Path(__file__).resolve().parent.parent
RAY = Path(sys.executable).parent / "ray"
START_TIMEOUT_S = 90


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def ray_head():
    """A running head: (its address, the env a driver needs: token auth on, the same token)."""
    if not RAY.is_file():
        pytest.skip(f"no ray executable beside {sys.executable}")
    temp = Path(tempfile.mkdtemp(prefix="rayc", dir="/tmp"))  # short: Ray's socket paths
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env.update(
        RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=secrets.token_hex(32), OPENBLAS_NUM_THREADS="1"
    )
    log = open(temp / "head.log", "w")  # closed in the finalizer below
    head = subprocess.Popen(
        [str(RAY), "start", "--head", "--block", "--num-cpus", "2", "--port", str(port),
         "--dashboard-port", str(free_port()), "--include-dashboard", "false",
         "--disable-usage-stats", "--temp-dir", str(temp / "ray")],
        env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while "Ray runtime started" not in (temp / "head.log").read_text():
            if head.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"ray start --head failed:\n{(temp / 'head.log').read_text()}")
            time.sleep(0.2)
        yield f"127.0.0.1:{port}", env
    finally:
        head.send_signal(signal.SIGTERM)  # --block: stops the processes it started, then exits
        try:
            head.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(head.pid, signal.SIGKILL)  # its own session: only what it started
            head.wait()
        log.close()
        shutil.rmtree(temp, ignore_errors=True)


def test_train_connects_to_a_running_cluster_and_samples_on_it(ray_head, tmp_path):
    address, env = ray_head
    proc = subprocess.run(
        [sys.executable, str(ROOT / "train.py"), "attacker", "--backend", "rllib",
         "--ray-address", address, "--num-env-runners", "1", "--total-timesteps", "200",
         "--n-steps", "200", "--batch-size", "100", "--n-epochs", "1",
         "--final-eval-episodes", "2", "--no-progress-bar", "--runs-root", str(tmp_path)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=240,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Connected to Ray cluster" in proc.stderr  # not a local Ray of its own
    assert "Started a local Ray instance" not in proc.stderr
    assert "(SingleAgentEnvRunner pid=" in proc.stderr  # the env runner is an actor there
    (run_dir,) = tmp_path.iterdir()
    scores = json.loads((run_dir / "scores.json").read_text())
    assert scores["iterations"] == 1 and 200 <= scores["timesteps"] <= 256
    assert scores["agent_returns"]["attacker"] > 0  # Φ at the window end is positive
    learned = scores["evaluations"]["learned (RLlib PPO)"]
    assert learned["reference"] == pytest.approx(0.0327856, rel=1e-5)  # EXS, ch4-position
    config = json.loads((run_dir / "config.json").read_text())
    assert config["config"]["run"]["ray_address"] == address
    assert config["config"]["run"]["num_env_runners"] == 1
