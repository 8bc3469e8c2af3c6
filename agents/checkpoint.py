"""Checkpoints that cannot run code: tensors, JSON and plain arrays, never pickle.

A saved model is a pair of files side by side:

- ``<name>.pt``: ``torch.save`` of ``{"state_dicts": {...}, "variables": {...}}``, the state
  dicts of the policy and of every optimizer (SB3's ``get_parameters``) and the loose tensors
  SB3 keeps (SAC's entropy coefficient). It is read with ``torch.load(weights_only=True)``, which
  rebuilds tensors and plain containers only and refuses any other object;
- ``<name>.json``: the format tag, the algorithm, its hyperparameters, ``num_timesteps``, the
  counters training continues from (``_n_updates``, ``_episode_num``, DQN's ``_n_calls`` and
  ``exploration_rate``), the ``.pt`` file's name and its SHA-256. No random-generator state.

A pair is written so that a kill at any moment leaves a loadable one (:func:`save_pair`): the
new tensors go to ``<name>.pt.next``, then the ``.json`` naming ``<name>.pt`` with the new
SHA-256 replaces the old one, then ``<name>.pt.next`` replaces ``<name>.pt``. Before the
``.json`` is replaced, the old pair is intact; after it, the staged tensors are the ones it
describes (:func:`tensor_file` reads them, and the next write finishes the move).

Loading rebuilds the model from its algorithm and hyperparameters on an env (for the spaces) and
loads the state dicts into it. A replay buffer is an ``.npz`` of its filled rows, read with
``np.load(allow_pickle=False)``.

stable-baselines3's own ``.zip`` files (and ``save_replay_buffer``'s pickles) are unpickled when
loaded and can run any code; they load only with ``trusted=True`` (``--trust-checkpoint``). Every
path a checkpoint names is resolved inside its run folder; one outside it (an absolute path,
``..``, a symlink pointing out) is refused.
"""

from __future__ import annotations

import errno
import hashlib
import itertools
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.save_util import recursive_getattr

from agents.algos import ALGO_CLASSES, build_model
from agents.config import HYPERPARAMETERS, Hyperparameters, algo_kwargs
from agents.runs import atomic_write, write_json

FORMAT = "fdia_env-sb3-state-v1"
BUFFER_FORMAT = "fdia_env-replay-buffer-v1"
# Counters SB3 continues from when training resumes (whichever the algorithm has).
COUNTERS = ("num_timesteps", "_n_updates", "_episode_num", "_n_calls", "exploration_rate")
BUFFER_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")
TRUST_HINT = (
    "pass --trust-checkpoint (trusted=True) to load it only if you made it yourself or trust "
    "whoever did"
)


class UntrustedCheckpointError(ValueError):
    """A checkpoint that can only be read by unpickling, asked for without ``trusted=True``."""


def inside(folder: Path, name: str | Path, root: Path, what: str = "checkpoint file") -> Path:
    """``folder / name`` resolved, which must lie inside ``root`` (the run folder).

    Raises:
        ValueError: For an absolute ``name``, one with ``..``, or one that resolves (through
            symlinks) outside ``root``; the message names the path and the run folder.
    """
    if not isinstance(name, str | Path) or not str(name):
        raise ValueError(f"{what} must be a file name inside the run folder {root}, got {name!r}")
    raw = Path(name)
    resolved_root = Path(root).resolve()
    if raw.is_absolute() or ".." in raw.parts:
        raise ValueError(
            f"{what} {str(name)!r} is outside the run folder {resolved_root}: only names inside "
            "it are loaded"
        )
    path = (Path(folder) / raw).resolve()
    if not path.is_relative_to(resolved_root):
        raise ValueError(
            f"{what} {str(name)!r} resolves to {path}, outside the run folder {resolved_root}: "
            "only files inside it are loaded"
        )
    return path


def read_json(path: Path, what: str = "file") -> dict[str, Any]:
    """A JSON object from ``path``.

    Raises:
        ValueError: For a missing, unreadable or corrupt file (naming it).
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{what} {path} does not exist")
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{what} {path} is corrupt or unreadable ({exc})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{what} {path} is corrupt: expected a JSON object")
    return data


# The largest step count or counter a run file may hold (2**53: exact as a JSON number).
MAX_COUNT = 2**53
# Hyperparameters whose size is allocated when a model is built: their largest allowed value.
SIZE_LIMITS = {"n_steps": 2**24, "batch_size": 2**24, "buffer_size": 2**31, "net_arch": 2**16}


def check_count(value: Any, what: str, path: Path, maximum: int = MAX_COUNT) -> int:
    """``value`` as an int, if it is an integer in ``[0, maximum]`` (a bool is not).

    Raises:
        ValueError: Naming ``what`` (the key), ``path`` and the allowed range.
    """
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= maximum:
        raise ValueError(
            f"{path} is corrupt: {what} must be an integer in [0, {maximum}], got {value!r}"
        )
    return value


def check_seconds(value: Any, what: str, path: Path) -> float:
    """``value`` as a float, if it is a finite number >= 0 (a bool is not).

    Raises:
        ValueError: Naming ``what`` and ``path``.
    """
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or value < 0
    ):
        raise ValueError(f"{path} is corrupt: {what} must be a finite number >= 0, got {value!r}")
    return float(value)


def hyperparameters_from(data: Any, path: Path, key: str = "hyperparameters") -> Hyperparameters:
    """The :class:`~agents.config.Hyperparameters` a run file holds under ``key``, checked.

    Every key must be a field of the dataclass, every value of its type and range (lists
    become tuples), and the sizes a model allocates (:data:`SIZE_LIMITS`) bounded.

    Raises:
        ValueError: Naming ``path``, ``key`` and the offending hyperparameter.
    """
    where = f"{path}: {key}"
    if not isinstance(data, dict):
        raise ValueError(f"{where} must be a JSON object of hyperparameters, got {data!r:.80}")
    unknown = sorted(str(k) for k in data if k not in HYPERPARAMETERS)
    if unknown:
        raise ValueError(
            f"{where} holds unknown hyperparameter(s) {', '.join(unknown)}; known: "
            f"{', '.join(HYPERPARAMETERS)}"
        )
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
    try:
        hp = Hyperparameters(**values)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where} is invalid: {exc}") from None
    for name, limit in SIZE_LIMITS.items():
        value = getattr(hp, name)
        sizes = value if isinstance(value, tuple) else () if value is None else (value,)
        if any(size > limit for size in sizes):
            raise ValueError(f"{where}: {name} {value!r} is too large (at most {limit} each)")
    return hp


def check_finite(payload: Any, path: Path, name: str = "") -> None:
    """Raise unless every floating-point tensor in ``payload`` (nested) is finite.

    Raises:
        ValueError: Naming ``path`` and the first tensor holding NaN or infinity.
    """
    if isinstance(payload, torch.Tensor):
        if payload.is_floating_point() and not bool(torch.isfinite(payload).all()):
            raise ValueError(
                f"tensor file {path} holds NaN or infinite weights ({name or 'a tensor'}); it "
                "was not loaded (a diverged run: resume from an earlier checkpoint)"
            )
    elif isinstance(payload, dict):
        for key, value in payload.items():
            check_finite(value, path, f"{name}.{key}" if name else str(key))
    elif isinstance(payload, list | tuple):
        for i, value in enumerate(payload):
            check_finite(value, path, f"{name}[{i}]")


def check_network_fits(net_arch: Any, tensors: dict[str, Any], path: Path, source: Path) -> None:
    """Raise when the hidden sizes ``net_arch`` need more weights than the stored ``tensors``.

    A network of hidden sizes h₁…h_k holds at least Σhᵢ + Σhᵢ₋₁hᵢ parameters; a description
    asking for more than its tensor file stores does not describe it (and would allocate
    memory for nothing): it is refused before anything is built.

    Raises:
        ValueError: Naming ``source`` (the description), its sizes and what ``path`` stores.
    """
    sizes = list(net_arch or [])
    need = sum(sizes) + sum(a * b for a, b in itertools.pairwise(sizes))
    stored = sum(t.numel() for t in tensors.values() if isinstance(t, torch.Tensor))
    if need > stored:
        raise ValueError(
            f"model description {source}: net_arch {sizes} needs at least {need:,} weights, "
            f"its tensor file {path} holds {stored:,}: they do not belong together"
        )


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


# ---------------------------------------------------------------------------- models


STAGED = ".next"  # suffix of the tensors save_pair writes before its description


def staged(tensors: Path) -> Path:
    """Where :func:`save_pair` writes the new tensors of ``tensors`` before its description."""
    return Path(tensors).with_name(Path(tensors).name + STAGED)


def tensor_file(meta: dict[str, Any], path: Path, root: Path) -> Path:
    """The tensor file a JSON description at ``path`` names, checked before anything loads it.

    When a write was stopped after the description was replaced and before its staged tensors
    were moved into place (:func:`save_pair`), the staged file is the one that matches; it is
    returned (and nothing is moved: a reader may not hold the run's lock).

    Raises:
        ValueError: For a file outside ``root``, a missing one or one whose SHA-256 is not the
            description's ``sha256``.
    """
    tensors = inside(path.parent, meta.get("tensors", ""), root, "tensor file")
    pending = inside(path.parent, staged(tensors).name, root, "tensor file")
    if tensors.is_file() and _sha256(tensors) == meta.get("sha256"):
        return tensors
    if pending.is_file() and _sha256(pending) == meta.get("sha256"):
        return pending
    if not tensors.is_file():
        raise ValueError(f"tensor file {tensors} named by {path} does not exist")
    raise ValueError(f"tensor file {tensors} does not match the SHA-256 recorded in {path}")


def write_tensors(path: Path, payload: Any) -> Path:
    """``torch.save(payload)`` to ``path`` atomically; a failed write is an :class:`OSError`.

    torch reports a write that fails part-way (a full disk) as a ``RuntimeError`` from its zip
    writer; it is raised as an ``OSError`` naming the file, as every other failed write is.
    """
    path = Path(path)
    try:
        return atomic_write(path, lambda fh: torch.save(payload, fh))
    except RuntimeError as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise OSError(errno.EIO, f"could not write {path} (is the disk full?): {first}") from None


def settle_pair(description: Path, tensors: Path) -> None:
    """Finish or discard a :func:`save_pair` that a kill stopped part-way.

    A staged ``<tensors>.next`` that the description names (by its SHA-256) replaces
    ``tensors``; one it does not name (the kill came before the description) is removed. Call
    it only while holding the run's lock.
    """
    pending = staged(tensors)
    if not pending.is_file():
        return
    try:
        meta = json.loads(Path(description).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        meta = None
    wanted = meta.get("sha256") if isinstance(meta, dict) else None
    if wanted is not None and _sha256(pending) == wanted:
        if not (Path(tensors).is_file() and _sha256(tensors) == wanted):
            os.replace(pending, tensors)
            return
    pending.unlink(missing_ok=True)


def save_pair(description: Path, tensors: Path, payload: Any, meta: dict[str, Any]) -> Path:
    """Write ``payload`` to ``tensors`` and ``meta`` to ``description`` so a kill loses nothing.

    The order (:func:`settle_pair` of an earlier stopped write, the tensors staged as
    ``<tensors>.next``, the description naming ``tensors`` with their SHA-256, the staged file
    moved into place) keeps a loadable pair on disk at every moment: the previous one until the
    description is replaced, the new one (read from the staged file) after.

    Args:
        description: The JSON file.
        tensors: The tensor file, in the same folder.
        payload: What ``torch.save`` writes (tensors and plain containers).
        meta: The description, without ``tensors`` and ``sha256`` (added here).

    Returns:
        ``description``.

    Raises:
        OSError: When a file cannot be written (naming it); the previous pair stays loadable.
    """
    description, tensors = Path(description), Path(tensors)
    settle_pair(description, tensors)
    pending = write_tensors(staged(tensors), payload)
    write_json(description, {**meta, "tensors": tensors.name, "sha256": _sha256(pending)})
    os.replace(pending, tensors)
    return description


def save_model(
    model: BaseAlgorithm, path: Path, algo: str, hyperparameters: dict[str, Any]
) -> Path:
    """Write ``path.with_suffix(".pt")`` and ``path.with_suffix(".json")`` (:func:`save_pair`).

    Args:
        model: The model to save.
        path: Either file of the pair (its suffix is replaced).
        algo: The algorithm's name (a key of :data:`~agents.algos.ALGO_CLASSES`).
        hyperparameters: Its resolved hyperparameters
            (:func:`~agents.config.resolved_hyperparameters`), to rebuild it.

    Returns:
        The ``.json`` path (what a loader is given).
    """
    path = Path(path)
    _, variable_names = model._get_torch_save_params()
    payload = {
        "state_dicts": model.get_parameters(),
        "variables": {
            name: recursive_getattr(model, name).detach().cpu().clone() for name in variable_names
        },
    }
    counters = {k: getattr(model, k) for k in COUNTERS if hasattr(model, k)}
    meta = {
        "format": FORMAT,
        "algo": algo,
        "hyperparameters": hyperparameters,
        "num_timesteps": int(model.num_timesteps),
        "counters": {k: v if isinstance(v, float) else int(v) for k, v in counters.items()},
    }
    return save_pair(path.with_suffix(".json"), path.with_suffix(".pt"), payload, meta)


def load_model(
    path: Path,
    env: Any,
    root: Path,
    device: str = "cpu",
    kwargs: dict[str, Any] | None = None,
    algo: str | None = None,
    trusted: bool = False,
) -> BaseAlgorithm:
    """The model saved at ``path`` (a ``.json`` from :func:`save_model`, or an SB3 ``.zip``).

    Args:
        path: The file to load, which must lie inside ``root``.
        env: An env with the model's spaces (a gym env or a vector env); the model is built
            on it.
        root: The run folder that must hold ``path`` and the files it names.
        device: torch device.
        kwargs: SB3 constructor kwargs (default: from the hyperparameters in the ``.json``).
        algo: The expected algorithm (checked against the file; required for a ``.zip``).
        trusted: Allow an SB3 ``.zip``, which is unpickled and can run code.

    Raises:
        UntrustedCheckpointError: For a ``.zip`` without ``trusted``.
        ValueError: For a path outside ``root``, a missing or corrupt file, a tensor file that
            holds anything but tensors and containers, or one that does not fit the model.
    """
    path = inside(Path(path).parent, Path(path).name, root, "model file")
    if path.suffix == ".zip":
        return load_sb3_zip(path, algo, trusted, env, device)
    if path.suffix != ".json":
        raise ValueError(
            f"model file {path}: expected a .json checkpoint description (with its .pt tensors) "
            "or, with --trust-checkpoint, a stable-baselines3 .zip"
        )
    meta = read_json(path, "model description")
    if meta.get("format") != FORMAT:
        raise ValueError(f"model description {path}: format {meta.get('format')!r}, not {FORMAT}")
    if algo is not None and meta.get("algo") != algo:
        raise ValueError(f"model description {path} holds a {meta.get('algo')} model, not {algo}")
    if not isinstance(meta.get("algo"), str) or meta["algo"] not in ALGO_CLASSES:
        raise ValueError(f"model description {path}: unknown algorithm {meta.get('algo')!r}")
    check_count(meta.get("num_timesteps", 0), "num_timesteps", path)
    counters = meta.get("counters", {})
    if not isinstance(counters, dict):
        raise ValueError(f"{path} is corrupt: counters must be a JSON object, got {counters!r:.80}")
    hp = hyperparameters_from(meta.get("hyperparameters"), path)
    tensors = tensor_file(meta, path, root)
    payload = load_tensors(tensors, device)
    if kwargs is None:  # to score it: its replay buffer is never filled, so it is kept small
        try:
            kwargs = algo_kwargs(meta["algo"], hp)
        except ValueError as exc:
            raise ValueError(f"{path}: hyperparameters: {exc}") from None
        if "buffer_size" in kwargs:
            kwargs["buffer_size"] = min(kwargs["buffer_size"], 2)
    net_arch = (kwargs.get("policy_kwargs") or {}).get("net_arch")
    check_network_fits(net_arch, payload["state_dicts"].get("policy", {}), tensors, path)
    try:
        model = build_model(meta["algo"], env, kwargs, seed=None, device=device)
    except (TypeError, ValueError, AssertionError) as exc:
        raise ValueError(f"{path}: the model it describes cannot be built: {exc}") from None
    restore(model, payload, counters, tensors)
    return model


def load_tensors(path: Path, device: str = "cpu") -> dict[str, Any]:
    """``torch.load(path, weights_only=True)``: tensors and plain containers, nothing else.

    Raises:
        ValueError: When the file holds other objects (a pickle that could run code is refused
            before anything in it runs), is not a torch file, or holds NaN or infinite weights.
    """
    try:
        payload = torch.load(path, map_location=device, weights_only=True)
    except Exception as exc:  # any failure to read untrusted bytes is a refusal
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(
            f"tensor file {path} is not a weights-only torch file and was not loaded ({first})"
        ) from None
    if (
        not isinstance(payload, dict)
        or not isinstance(payload.get("state_dicts"), dict)
        or not isinstance(payload.get("variables"), dict)
        or not all(isinstance(v, dict) for v in payload["state_dicts"].values())
    ):
        raise ValueError(f"tensor file {path} does not hold a {FORMAT} checkpoint")
    check_finite(payload, path)
    return payload


def restore(
    model: BaseAlgorithm, payload: dict[str, Any], counters: dict[str, Any], source: Path
) -> None:
    """Load the state dicts, tensors and counters of a checkpoint into a freshly built model.

    Raises:
        ValueError: When they do not fit the model (another algorithm or network).
    """
    state_names, variable_names = model._get_torch_save_params()
    if set(payload["state_dicts"]) != set(state_names) or set(payload["variables"]) != set(
        variable_names
    ):
        raise ValueError(
            f"checkpoint {source} holds {sorted(payload['state_dicts'])} and "
            f"{sorted(payload['variables'])}; the model needs {sorted(state_names)} and "
            f"{sorted(variable_names)}"
        )
    try:
        model.set_parameters(payload["state_dicts"], exact_match=True, device=model.device)
        for name, tensor in payload["variables"].items():
            target = recursive_getattr(model, name)
            if not isinstance(tensor, torch.Tensor) or tensor.shape != target.shape:
                raise ValueError(f"variable {name} has the wrong shape")
            target.data.copy_(tensor)
    except (RuntimeError, ValueError, KeyError, TypeError, IndexError, AttributeError) as exc:
        raise ValueError(
            f"checkpoint {source} does not fit the model built from the run's config: {exc}"
        ) from None
    for name, value in counters.items():
        if name not in COUNTERS or not hasattr(model, name):
            continue
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"checkpoint {source}: counter {name} is not a number: {value!r}")
        setattr(model, name, value)


def require_trusted(path: Path, trusted: bool, what: str = "a stable-baselines3 .zip") -> None:
    """Raise :class:`UntrustedCheckpointError` for a pickle-based file unless ``trusted``."""
    if not trusted:
        raise UntrustedCheckpointError(
            f"{path} is {what}, which is loaded by unpickling and can run any code; it was not "
            f"loaded: {TRUST_HINT}"
        )


def load_sb3_zip(
    path: Path, algo: str | None, trusted: bool, env: Any = None, device: str = "cpu"
) -> BaseAlgorithm:
    """A stable-baselines3 ``.zip``: SB3's own ``load``, which unpickles, so only when trusted.

    The project's one path to an SB3 ``.zip`` (training's resume and the scorer's agents).

    Args:
        path: The ``.zip``.
        algo: Its algorithm, a key of :data:`agents.algos.ALGO_CLASSES`.
        trusted: The user marked it as trusted (``--trust-checkpoint``).
        env: The env the model is built on (SB3 checks its spaces), or None.
        device: torch device.

    Raises:
        UntrustedCheckpointError: Without ``trusted``, before anything is read.
        ValueError: For a missing ``algo`` or one that is not known, or a missing file.
    """
    require_trusted(path, trusted)
    if algo is None:
        raise ValueError(
            f"algo is needed to load the stable-baselines3 .zip {path}: one of "
            f"{', '.join(ALGO_CLASSES)} (--algo)"
        )
    if algo not in ALGO_CLASSES:
        raise ValueError(f"algo must be one of {', '.join(ALGO_CLASSES)}, got {algo!r}")
    if not Path(path).is_file():
        raise ValueError(f"model file {path} does not exist")
    return ALGO_CLASSES[algo].load(path, env=env, device=device)


# ---------------------------------------------------------------------------- replay buffers


def save_replay_buffer(buffer: ReplayBuffer, path: Path) -> Path:
    """Write the filled rows of ``buffer`` (and its position) as an ``.npz``, atomically."""
    filled = buffer.buffer_size if buffer.full else buffer.pos
    arrays: dict[str, np.ndarray] = {
        "format": np.array(BUFFER_FORMAT),
        "buffer_size": np.array(buffer.buffer_size),
        "pos": np.array(buffer.pos),
        "full": np.array(bool(buffer.full)),
    }
    for name in BUFFER_ARRAYS:
        value = getattr(buffer, name, None)
        if isinstance(value, dict):
            arrays.update({f"{name}.{k}": v[:filled] for k, v in value.items()})
        elif value is not None:
            arrays[name] = value[:filled]
    return atomic_write(Path(path), lambda fh: np.savez(fh, **arrays))


def load_replay_buffer(model: BaseAlgorithm, path: Path, root: Path, trusted: bool = False) -> None:
    """Fill ``model.replay_buffer`` from :func:`save_replay_buffer`'s ``.npz``.

    A ``.pkl`` from SB3's ``save_replay_buffer`` is unpickled, so it loads only with
    ``trusted=True``.

    Raises:
        UntrustedCheckpointError: For a ``.pkl`` without ``trusted``.
        ValueError: For a path outside ``root``, a missing or corrupt file, or arrays that do
            not fit the model's buffer.
    """
    path = inside(Path(path).parent, Path(path).name, root, "replay buffer file")
    if not path.is_file():
        raise ValueError(f"replay buffer file {path} does not exist")
    if path.suffix == ".pkl":
        require_trusted(path, trusted, "a pickled replay buffer")
        model.load_replay_buffer(path)
        return
    buffer = model.replay_buffer
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (ValueError, OSError, EOFError) as exc:  # includes "pickled data" refusals
        raise ValueError(f"replay buffer file {path} is not a plain .npz ({exc})") from None
    if str(arrays.get("format", "")) != BUFFER_FORMAT:
        raise ValueError(f"replay buffer file {path} is not a {BUFFER_FORMAT} file")
    size, pos, full = (arrays[k].item() for k in ("buffer_size", "pos", "full"))
    if size != buffer.buffer_size:
        raise ValueError(
            f"replay buffer file {path} holds a buffer of {size} rows, the model's has "
            f"{buffer.buffer_size} (--buffer-size)"
        )
    filled = size if full else pos
    if not 0 <= pos < size:
        raise ValueError(f"replay buffer file {path}: position {pos} outside [0, {size})")
    targets: dict[str, np.ndarray] = {}
    for name in BUFFER_ARRAYS:
        value = getattr(buffer, name, None)
        if isinstance(value, dict):
            targets.update({f"{name}.{k}": v for k, v in value.items()})
        elif value is not None:
            targets[name] = value
    if set(targets) != set(arrays) - {"format", "buffer_size", "pos", "full"}:
        raise ValueError(
            f"replay buffer file {path} holds {sorted(arrays)}, the model's buffer needs "
            f"{sorted(targets)}"
        )
    for name, target in targets.items():
        src = arrays[name]
        if src.shape != (filled, *target.shape[1:]) or src.dtype != target.dtype:
            raise ValueError(
                f"replay buffer file {path}: {name} has shape {src.shape} {src.dtype}, expected "
                f"{(filled, *target.shape[1:])} {target.dtype}"
            )
    for name, target in targets.items():
        target[:filled] = arrays[name]
    buffer.pos, buffer.full = int(pos), bool(full)
