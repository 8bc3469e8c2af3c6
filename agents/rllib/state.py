"""Resumable RLlib runs without pickles: RL-module weights, optimizer state and counters.

RLlib's own checkpoints (``Algorithm.save_to_path``) hold pickles (the algorithm's class and
constructor arguments, the connectors), which run code when loaded. ``--resume`` of a
``--backend rllib`` run reads none of them; it reads a pair of files in the run folder instead:

- ``rllib_state.pt``: ``torch.save`` of ``{"state_dicts": {...}, "variables": {...}}`` (the
  format of :mod:`agents.checkpoint`): each RL module's weights (``rl_module/<module>``), each
  optimizer's state dict (``optimizer/<name>``: Adam's moments and step counts, its param
  groups) and PPO's adaptive KL coefficient per module (``kl_coeff/<module>``). It is read with
  ``torch.load(weights_only=True)`` (:func:`agents.checkpoint.load_tensors`), which builds
  tensors and plain containers only;
- ``rllib_state.json``: the format tag, RLlib's training iteration, RLlib's lifetime counters
  (env steps sampled, which drive the learning-rate schedule, module steps trained, episodes),
  the module and optimizer names, the ``.pt`` file's name and SHA-256, and what the caller adds
  (the run's env steps, seconds, iterations; the self-play loop's state).

Resuming rebuilds the algorithm from the run's config.json (:func:`agents.rllib.config.ppo_config`)
and loads these into it (:func:`restore_state`); the env runners get the restored weights.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

FORMAT = "fdia_env-rllib-state-v1"
STATE = "rllib_state.json"  # a run folder that --resume can continue holds it
TENSORS = "rllib_state.pt"
# RLlib's lifetime counters kept across a resume (Stats states of its MetricsLogger: plain JSON)
LIFETIME_STATS = ("lifetime_sum",)
_STATS_KEYS = frozenset(
    {"stats_cls_identifier", "is_root", "is_leaf", "latest_merged", "lifetime_sum",
     "track_throughputs"}
)  # fmt: skip


def _to_tensors(tree: Any) -> Any:
    """Numpy arrays and scalars in a nested dict/list as torch tensors (for weights_only)."""
    import torch

    if isinstance(tree, dict):
        return {k: _to_tensors(v) for k, v in tree.items()}
    if isinstance(tree, list | tuple):
        return type(tree)(_to_tensors(v) for v in tree)
    if isinstance(tree, np.ndarray | np.generic):
        return torch.as_tensor(np.asarray(tree)).clone()
    if isinstance(tree, torch.Tensor):
        return tree.detach().cpu().clone()
    return tree


def _learner(algo: Any) -> Any:
    group = algo.learner_group
    if not group.is_local:
        raise ValueError("saving an RLlib run's state needs a local learner (num_learners=0)")
    return group._learner


def lifetime_stats(algo: Any) -> dict[str, Any]:
    """RLlib's lifetime counters of ``algo`` (its MetricsLogger Stats states, JSON-ready)."""
    stats = algo.metrics.get_state()["stats"]
    out = {}
    for key, state in stats.items():
        if state.get("stats_cls_identifier") in LIFETIME_STATS:
            out[key] = {k: _plain(v) for k, v in state.items() if k in _STATS_KEYS}
    return out


def _plain(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if hasattr(value, "item") and getattr(value, "ndim", 1) == 0:
        return value.item()
    return value


def save_state(algo: Any, run_dir: Path, extra: dict[str, Any] | None = None) -> Path:
    """Write ``rllib_state.pt`` and ``rllib_state.json`` in ``run_dir`` (a kill loses nothing).

    :func:`agents.checkpoint.save_pair` keeps a readable pair on disk at every moment.

    Args:
        algo: A built RLlib algorithm (local learner).
        run_dir: The run folder.
        extra: JSON-ready entries the caller resumes from (steps, seconds, loop state).

    Returns:
        The ``.json`` path.
    """
    from agents.checkpoint import save_pair

    learner = _learner(algo)
    state = algo.learner_group.get_state(components=["learner/rl_module", "learner/optimizer"])
    modules = state["learner"]["rl_module"]
    optimizers = state["learner"].get("optimizer", {})
    state_dicts = {f"rl_module/{m}": _to_tensors(dict(sd)) for m, sd in modules.items()}
    for name, opt in optimizers.items():
        state_dicts[f"optimizer/{name}"] = _to_tensors(opt["state"])
    kl = getattr(learner, "curr_kl_coeffs_per_module", {})
    variables = {f"kl_coeff/{m}": _to_tensors(kl[m]).reshape(()) for m in modules if m in kl}
    payload = {"state_dicts": state_dicts, "variables": variables}
    path = Path(run_dir)
    meta = {
        "format": FORMAT,
        "iteration": int(algo.iteration),
        "modules": sorted(modules),
        "optimizers": {name: str(opt["module_id"]) for name, opt in optimizers.items()},
        "lifetime_stats": lifetime_stats(algo),
        **(extra or {}),
    }
    return save_pair(path / STATE, path / TENSORS, payload, meta)


def read_state(run_dir: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """The description and the tensors of a run's saved state, checked, never unpickled.

    Raises:
        ValueError: For a missing, corrupt or foreign description, a tensor file outside the
            run folder, one whose SHA-256 differs from the recorded one, or one that holds
            anything but tensors and plain containers (a pickle that could run code is refused
            before anything in it runs).
    """
    from agents.checkpoint import inside, load_tensors, read_json, tensor_file

    root = Path(run_dir)
    path = inside(root, STATE, root, "RLlib state file")
    meta = read_json(path, "RLlib state")
    if meta.get("format") != FORMAT:
        raise ValueError(f"RLlib state {path}: format {meta.get('format')!r}, not {FORMAT}")
    for key, kind in (("iteration", int), ("modules", list), ("optimizers", dict)):
        if not isinstance(meta.get(key), kind) or isinstance(meta.get(key), bool):
            raise ValueError(f"RLlib state {path} is corrupt: {key!r} is not a {kind.__name__}")
    tensors = tensor_file(meta, path, root)
    payload = load_tensors(tensors)
    expected = {f"rl_module/{m}" for m in meta["modules"]} | {
        f"optimizer/{name}" for name in meta["optimizers"]
    }
    if set(payload["state_dicts"]) != expected:
        raise ValueError(
            f"tensor file {tensors} holds {sorted(payload['state_dicts'])}; {path} lists "
            f"{sorted(expected)}"
        )
    return meta, payload


def restore_state(algo: Any, meta: dict[str, Any], payload: dict[str, Any], source: Path) -> None:
    """Load :func:`read_state`'s weights, optimizer state and counters into a fresh algorithm.

    The env runners get the restored weights; RLlib's iteration and lifetime counters (and so
    the learning-rate schedule) continue from the saved ones.

    Raises:
        ValueError: When they do not fit the algorithm built from the run's config (other
            modules, layers or shapes).
    """
    import torch

    learner = _learner(algo)
    current = algo.learner_group.get_state(components=["learner/rl_module"])["learner"]
    have = current["rl_module"]
    if set(have) != set(meta["modules"]):
        raise ValueError(
            f"checkpoint {source} holds the RL modules {sorted(meta['modules'])}; the run's "
            f"config builds {sorted(have)}"
        )
    modules = {}
    for m in meta["modules"]:
        saved = payload["state_dicts"][f"rl_module/{m}"]
        want = {k: tuple(np.shape(v)) for k, v in have[m].items()}
        got = {k: tuple(v.shape) for k, v in saved.items() if isinstance(v, torch.Tensor)}
        if got != want or len(got) != len(saved):
            diff = sorted(set(want.items()) ^ set(got.items()))[:4]
            raise ValueError(
                f"checkpoint {source}: the weights of RL module {m!r} do not fit the network "
                f"built from the run's config (first differences: {diff})"
            )
        modules[m] = saved
    optimizers = {
        name: {"module_id": module_id, "state": payload["state_dicts"][f"optimizer/{name}"]}
        for name, module_id in meta["optimizers"].items()
    }
    state: dict[str, Any] = {"learner_group": {"learner": {"rl_module": modules}}}
    if optimizers:
        state["learner_group"]["learner"]["optimizer"] = optimizers
    state["training_iteration"] = meta["iteration"]
    try:
        algo.set_state(state)
    except (RuntimeError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"checkpoint {source} does not fit the run's algorithm: {exc}") from None
    kl = getattr(learner, "curr_kl_coeffs_per_module", None)
    for name, tensor in payload["variables"].items():
        kind, _, m = name.partition("/")
        if kind != "kl_coeff" or kl is None or m not in meta["modules"]:
            raise ValueError(f"checkpoint {source}: unexpected variable {name!r}")
        if not isinstance(tensor, torch.Tensor) or tensor.numel() != 1:
            raise ValueError(f"checkpoint {source}: {name} is not a scalar tensor")
        kl[m].data.fill_(float(tensor))
    _restore_lifetime_stats(algo, meta.get("lifetime_stats", {}), source)


def _restore_lifetime_stats(algo: Any, saved: Any, source: Path) -> None:
    if not isinstance(saved, dict):
        raise ValueError(f"checkpoint {source}: 'lifetime_stats' is not an object")
    stats = {}
    for key, state in saved.items():
        ok = (
            isinstance(key, str)
            and isinstance(state, dict)
            and state.get("stats_cls_identifier") in LIFETIME_STATS
            and set(state) <= _STATS_KEYS
            and all(
                isinstance(state.get(k), int | float) and math.isfinite(state[k])
                for k in ("lifetime_sum",)
            )
        )
        if not ok:
            raise ValueError(f"checkpoint {source}: lifetime counter {key!r} is corrupt")
        stats[key] = state
    if stats:
        current = algo.metrics.get_state()
        current["stats"].update(stats)
        algo.metrics.set_state(current)


def module_weights(algo: Any, module: str) -> dict[str, Any]:
    """The learner's weights of RL module ``module`` as torch tensors (for tests and checks)."""
    state = algo.learner_group.get_state(components=[f"learner/rl_module/{module}"])
    return _to_tensors(dict(state["learner"]["rl_module"][module]))


# ---------------------------------------------------------------------------- single policies


def save_module(module: Any, path: Path) -> dict[str, Any]:
    """Write one RL module's weights (``{"state_dicts": {"rl_module": ...}}``) atomically.

    Returns:
        Its record for a state file: the file's name relative to the state's folder, its
        SHA-256, and whether the module is RLlib's inference-only form.
    """
    from agents.checkpoint import _sha256, write_tensors

    weights = _to_tensors(dict(module.state_dict()))
    payload = {"state_dicts": {"rl_module": weights}, "variables": {}}
    path = write_tensors(Path(path), payload)
    return {
        "file": path.name,
        "sha256": _sha256(path),
        "inference_only": bool(getattr(module, "inference_only", False)),
    }


def load_module(config: Any, env: Any, record: Any, folder: Path, root: Path) -> Any:
    """An RL module built from ``config`` for ``env``'s spaces, with :func:`save_module`'s weights.

    Raises:
        ValueError: For a corrupt record, a file outside ``root``, a SHA-256 that differs, a
            file that is not weights-only, or weights that do not fit the module.
    """
    from agents.checkpoint import _sha256, inside, load_tensors

    if not isinstance(record, dict) or not isinstance(record.get("inference_only"), bool):
        raise ValueError(f"policy record {record!r} in {root / STATE} is corrupt")
    path = inside(Path(folder), record.get("file", ""), root, "policy file")
    if not path.is_file():
        raise ValueError(f"policy file {path} named by {root / STATE} does not exist")
    if _sha256(path) != record.get("sha256"):
        raise ValueError(
            f"policy file {path} does not match the SHA-256 recorded in {root / STATE}"
        )
    payload = load_tensors(path)
    weights = payload["state_dicts"].get("rl_module")
    if not isinstance(weights, dict):
        raise ValueError(f"policy file {path} holds no RL module weights")
    spec = config.get_rl_module_spec(env=env, inference_only=record["inference_only"])
    module = spec.build()
    try:
        module.load_state_dict(weights, strict=True)
    except (RuntimeError, TypeError) as exc:
        first = str(exc).strip().splitlines()[0]
        raise ValueError(f"policy file {path} does not fit the run's network: {first}") from None
    module.eval()
    return module
