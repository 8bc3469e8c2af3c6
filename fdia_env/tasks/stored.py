"""Checks of the stored benchmark data: digests kept in the code, and each entry's form.

The task references (``references.json``) and the stored payoff matrices (``payoffs.json`` and
the ``.npy`` files it lists) are data files anyone can edit. Their SHA-256 digests are kept in
:mod:`fdia_env.tasks.digests`, a module that ``python -m agents.bench compute`` and
``python -m agents.bench payoff`` rewrite together with the files, so a file edited by hand
(an optimum changed, a payoff file swapped) is refused when it is read, before any score is
normalised with it. Every entry is checked too (keys, types, finite numbers), and each
failure is a :class:`StoredDataError` that names the file, the entry and what is wrong.
"""

from __future__ import annotations

import hashlib
import importlib
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

PACKAGE = Path(__file__).resolve().parent
DIGESTS_MODULE = "fdia_env.tasks.digests"
DIGESTS_PATH = PACKAGE / "digests.py"
SHA256 = re.compile(r"^[0-9a-f]{64}$")
PAYOFF_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*\.npy$")


class StoredDataError(ValueError):
    """A stored reference or payoff file that is changed, malformed or out of its folder."""


def read_stored(path: Path) -> bytes:
    """The bytes of the stored file ``path`` (``StoredDataError`` naming it if unreadable)."""
    try:
        return path.read_bytes()
    except OSError as exc:
        raise StoredDataError(
            f"{path}: cannot be read ({exc.strerror or exc}); reinstall fdia_env or restore "
            "the file from the repository"
        ) from None


def sha256_bytes(data: bytes) -> str:
    """The SHA-256 of ``data`` (hex)."""
    return hashlib.sha256(data).hexdigest()


def recorded() -> Any:
    """The module of recorded digests (:mod:`fdia_env.tasks.digests`)."""
    return importlib.import_module(DIGESTS_MODULE)


def check_digest(path: Path, data: bytes, expected: str | None, how: str, fix: str = "") -> None:
    """Raise unless ``data`` (the bytes of ``path``) has the SHA-256 ``expected``.

    Args:
        path: The file, for the message.
        data: Its bytes.
        expected: The recorded digest (None: the file has none recorded).
        how: The command that writes the file and its digest, for the message.
        fix: Another way to a good file than ``git checkout``, for the message.

    Raises:
        StoredDataError: Naming ``path`` and both digests.
    """
    got = sha256_bytes(data)
    if expected is None:
        raise StoredDataError(
            f"{path}: no SHA-256 is recorded for this file in {DIGESTS_PATH.name} (a file "
            f"added by hand); only {how} writes it with its digest"
        )
    if got != expected:
        raise StoredDataError(
            f"{path}: SHA-256 {got} is not the one recorded in {DIGESTS_PATH.name} "
            f"({expected}): the file was changed by hand (only {how} writes it with its "
            f"digest); restore it with git checkout{fix}"
        )


def write_digests(references: Path, manifest: Path, payoff_folder: Path) -> Path:
    """Rewrite :mod:`fdia_env.tasks.digests` from the package's files; its path.

    Args:
        references: ``references.json``.
        manifest: ``payoffs.json`` (absent: no stored payoffs).
        payoff_folder: The folder of the ``.npy`` files ``payoffs.json`` lists.
    """
    import json

    ref = sha256_bytes(references.read_bytes())
    man = sha256_bytes(manifest.read_bytes()) if manifest.is_file() else None
    names = sorted(json.loads(manifest.read_text(encoding="utf-8"))) if man else []
    files = {n: sha256_bytes((payoff_folder / n).read_bytes()) for n in names}
    lines = [
        '"""SHA-256 of the stored benchmark data, checked when it is read (fdia_env.tasks.stored).',
        "",
        "Written by ``python -m agents.bench compute`` and ``python -m agents.bench payoff``",
        "together with the files: do not edit by hand.",
        '"""',
        "",
        f'REFERENCES = "{ref}"',
        f"PAYOFF_MANIFEST = {None if man is None else repr(man).replace(chr(39), chr(34))}",
        "PAYOFF_FILES = {",
        *(_fit(f'    "{n}": "{h}",') for n, h in files.items()),
        "}",
        "",
    ]
    DIGESTS_PATH.write_text("\n".join(lines), encoding="utf-8")
    importlib.reload(recorded())
    return DIGESTS_PATH


def _fit(line: str) -> str:
    return line if len(line) <= 100 else f"{line}  # noqa: E501"


# ------------------------------------------------------------------------------ entry checks


class _Entry:
    """Checks of one entry of a stored file, each failure naming the file, entry and key."""

    def __init__(self, path: Path, entry: str) -> None:
        self.path, self.entry = path, entry

    def fail(self, key: str, what: str) -> StoredDataError:
        where = f"{self.path}: entry {self.entry!r}"
        return StoredDataError(f"{where}, {key}: {what}" if key else f"{where}: {what}")

    def mapping(self, value: Any, key: str, keys: tuple[str, ...], optional: tuple = ()) -> dict:
        if not isinstance(value, Mapping):
            raise self.fail(key, f"must be an object, got {_show(value)}")
        missing = [k for k in keys if k not in value]
        unknown = [k for k in value if k not in keys and k not in optional]
        if missing:
            raise self.fail(key, f"missing key(s) {', '.join(map(repr, missing))}")
        if unknown:
            raise self.fail(key, f"unknown key(s) {', '.join(map(repr, map(str, unknown)))}")
        return dict(value)

    def number(self, value: Any, key: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(key, f"must be a number, got {_show(value)}")
        if not math.isfinite(value):
            raise self.fail(key, f"must be a finite number, got {value!r}")
        return float(value)

    def integer(self, value: Any, key: str, low: int = 0) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise self.fail(key, f"must be an integer >= {low}, got {_show(value)}")
        return value

    def text(self, value: Any, key: str) -> str:
        if not isinstance(value, str):
            raise self.fail(key, f"must be a string, got {_show(value)}")
        return value

    def flag(self, value: Any, key: str) -> bool:
        if not isinstance(value, bool):
            raise self.fail(key, f"must be true or false, got {_show(value)}")
        return value


def _show(value: Any) -> str:
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) < 60 else text[:57] + '...'}"


REFERENCE_KEYS = (
    "objective",
    "metric",
    "random",
    "heuristics",
    "optimum",
    "game_value",
    "solvers",
    "date",
)
RANDOM_KEYS = ("mean", "ci95", "episodes", "seed")
OPTIMUM_KEYS = ("value", "name", "certified", "bound", "gap")


def check_reference_entry(path: Path, name: str, data: Any) -> dict[str, Any]:
    """The entry ``name`` of ``references.json`` checked: its JSON form with plain floats.

    Raises:
        StoredDataError: Naming ``path``, the entry and the key for a missing or unknown key,
            a value of the wrong type, or a NaN or infinite number.
    """
    e = _Entry(path, name)
    d = e.mapping(data, "", REFERENCE_KEYS, optional=("seconds",))
    rand = e.mapping(d["random"], "random", RANDOM_KEYS)
    opt = e.mapping(d["optimum"], "optimum", OPTIMUM_KEYS)
    heur = d["heuristics"]
    if not isinstance(heur, Mapping):
        raise e.fail("heuristics", f"must be an object, got {_show(heur)}")
    solvers = d["solvers"]
    if not isinstance(solvers, Mapping) or not all(isinstance(v, str) for v in solvers.values()):
        raise e.fail("solvers", f"must map packages to version strings, got {_show(solvers)}")
    out = {
        "objective": e.text(d["objective"], "objective"),
        "metric": e.text(d["metric"], "metric"),
        "random": {
            "mean": e.number(rand["mean"], "random.mean"),
            "ci95": e.number(rand["ci95"], "random.ci95"),
            "episodes": e.integer(rand["episodes"], "random.episodes"),
            "seed": e.integer(rand["seed"], "random.seed"),
        },
        "heuristics": {str(k): e.number(v, f"heuristics[{k!r}]") for k, v in heur.items()},
        "optimum": {
            "value": e.number(opt["value"], "optimum.value"),
            "name": e.text(opt["name"], "optimum.name"),
            "certified": e.flag(opt["certified"], "optimum.certified"),
            "bound": e.number(opt["bound"], "optimum.bound"),
            "gap": e.number(opt["gap"], "optimum.gap"),
        },
        "game_value": None if d["game_value"] is None else e.number(d["game_value"], "game_value"),
        "solvers": dict(solvers),
        "date": e.text(d["date"], "date"),
    }
    if "seconds" in d:
        out["seconds"] = e.number(d["seconds"], "seconds")
    return out


def check_references(path: Path, data: bytes, expected: str | None) -> dict[str, dict[str, Any]]:
    """Parse and check ``references.json``: task name → its checked JSON entry.

    Args:
        path: The file, for the messages.
        data: Its bytes.
        expected: Its recorded SHA-256; None checks the entries only (a file outside the
            package, or one being rewritten).

    Raises:
        StoredDataError: Naming ``path`` (and the entry and key) for a changed file, invalid
            JSON or an invalid entry.
    """
    import json

    if expected is not None:
        check_digest(
            path,
            data,
            expected,
            "python -m agents.bench compute",
            " or recompute every task with python -m agents.bench compute --all",
        )
    try:
        parsed = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise StoredDataError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(parsed, dict):
        raise StoredDataError(f"{path}: must hold an object (task name → references)")
    return {name: check_reference_entry(path, name, entry) for name, entry in parsed.items()}


PAYOFF_KEYS = (
    "scenario",
    "power",
    "allocation",
    "max_subset_size",
    "fingerprint",
    "shape",
    "sha256",
)


def payoff_path(manifest: Path, folder: Path, name: Any) -> Path:
    """The file a ``payoffs.json`` entry names: a plain ``.npy`` name inside ``folder``.

    Raises:
        StoredDataError: Naming ``manifest`` and the entry for an absolute path, a path with
            separators or ``..``, or one that resolves outside ``folder``.
    """
    if not isinstance(name, str) or not PAYOFF_NAME.fullmatch(name) or ".." in name:
        raise StoredDataError(
            f"{manifest}: entry {name!r}: a payoff file must be a plain file name ending in "
            f".npy inside {folder} (letters, digits, '.', '_', '-'; no separators, no '..')"
        )
    path = (folder / name).resolve()
    try:
        path.relative_to(folder.resolve())
    except ValueError:
        raise StoredDataError(
            f"{manifest}: entry {name!r}: resolves to {path}, outside {folder}"
        ) from None
    return path


def check_payoff_entry(manifest: Path, name: str, data: Any) -> dict[str, Any]:
    """The entry ``name`` of ``payoffs.json`` checked (see :func:`check_reference_entry`)."""
    e = _Entry(manifest, name)
    d = e.mapping(data, "", PAYOFF_KEYS)
    size = d["max_subset_size"]
    fp, shape, digest = d["fingerprint"], d["shape"], d["sha256"]
    if not isinstance(fp, list) or len(fp) != 8:
        raise e.fail("fingerprint", f"must be a list of 8 numbers, got {_show(fp)}")
    if not isinstance(shape, list) or len(shape) != 2:
        raise e.fail("shape", f"must be a list of 2 positive integers, got {_show(shape)}")
    if not isinstance(digest, str) or not SHA256.fullmatch(digest):
        raise e.fail("sha256", f"must be 64 lowercase hex digits, got {_show(digest)}")
    return {
        "scenario": e.text(d["scenario"], "scenario"),
        "power": e.number(d["power"], "power"),
        "allocation": e.text(d["allocation"], "allocation"),
        "max_subset_size": None if size is None else e.integer(size, "max_subset_size", 1),
        "fingerprint": [e.number(v, f"fingerprint[{i}]") for i, v in enumerate(fp)],
        "shape": [e.integer(v, f"shape[{i}]", 1) for i, v in enumerate(shape)],
        "sha256": digest,
    }


def check_payoff_manifest(
    path: Path, folder: Path, data: bytes, expected: str | None
) -> dict[str, dict[str, Any]]:
    """Parse and check ``payoffs.json``: file name → its checked entry.

    Args:
        path: ``payoffs.json``, for the messages.
        folder: The folder its files must lie in.
        data: Its bytes.
        expected: Its recorded SHA-256 (None: entries only, for a store outside the package).

    Raises:
        StoredDataError: Naming ``path`` (and the entry and key).
    """
    import json

    if expected is not None:
        check_digest(path, data, expected, "python -m agents.bench payoff")
    try:
        parsed = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise StoredDataError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(parsed, dict):
        raise StoredDataError(f"{path}: must hold an object (file name → game)")
    out = {}
    for name, entry in parsed.items():
        payoff_path(path, folder, name)
        out[name] = check_payoff_entry(path, name, entry)
    return out
