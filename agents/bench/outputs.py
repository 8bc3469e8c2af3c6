"""Output paths of the benchmark's commands, checked before the work and written with clear errors.

A file the commands create (``score --json``) gets its missing parent folders created; a page
they update in place (``table --page``) must exist. A folder given as a file, a parent that is
a file, or a location that cannot be written is a :class:`OutputPathError` naming the option
and the path, raised before any scoring starts (and again if the write itself fails).
"""

from __future__ import annotations

from pathlib import Path


class OutputPathError(ValueError):
    """An output option whose path cannot be written."""


def _fail(option: str, path: Path, why: str) -> OutputPathError:
    return OutputPathError(f"{option} {path}: {why}")


def check_new_file(option: str, path: Path) -> Path:
    """Check that ``path`` can be written as a file, creating its missing parent folders.

    Args:
        option: The command-line option, for the message (``"--json"``).
        path: The file to write.

    Raises:
        OutputPathError: For a folder, a parent that is not a folder or cannot be created, or
            a location without write permission.
    """
    path = Path(path)
    if path.is_dir():
        raise _fail(option, path, "is a folder; give a file path")
    parent = path.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise _fail(option, path, f"its parent {parent} is not a folder") from None
    except OSError as exc:
        raise _fail(option, path, f"cannot create its folder {parent} ({exc.strerror})") from None
    existed = path.exists()
    try:  # a real probe: permissions alone say nothing for root or a read-only file system
        with open(path, "a", encoding="utf-8"):
            pass
    except OSError as exc:
        raise _fail(option, path, f"cannot be written ({exc.strerror or exc})") from None
    if not existed:
        path.unlink(missing_ok=True)
    return path


def check_existing_file(option: str, path: Path) -> Path:
    """Check that ``path`` is an existing file that can be read and written (a page to update).

    Raises:
        OutputPathError: For a missing path, a folder or a file that cannot be read or written.
    """
    path = Path(path)
    if not path.exists():
        raise _fail(option, path, "does not exist (give the page to update)")
    if path.is_dir():
        raise _fail(option, path, "is a folder; give the page's file path")
    try:  # a real probe (opened for appending, nothing written)
        with open(path, "r+", encoding="utf-8"):
            pass
    except OSError as exc:
        raise _fail(option, path, f"cannot be read and written ({exc.strerror or exc})") from None
    return path


def write_text(option: str, path: Path, text: str) -> None:
    """Write ``text`` to ``path`` (UTF-8).

    Raises:
        OutputPathError: Naming ``option`` and ``path`` when the write fails.
    """
    try:
        Path(path).write_text(text, encoding="utf-8")
    except IsADirectoryError:
        raise _fail(option, path, "is a folder; give a file path") from None
    except OSError as exc:
        raise _fail(option, path, f"cannot be written ({exc.strerror or exc})") from None


def read_text(option: str, path: Path) -> str:
    """The text of ``path`` (UTF-8).

    Raises:
        OutputPathError: Naming ``option`` and ``path`` when it cannot be read.
    """
    try:
        return Path(path).read_text(encoding="utf-8")
    except IsADirectoryError:
        raise _fail(option, path, "is a folder; give a file path") from None
    except FileNotFoundError:
        raise _fail(option, path, "does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise _fail(option, path, f"cannot be read ({exc})") from None
