"""Atomic file writes: temp file, fsync, rename, fsync of the directory; previous versions kept."""

from __future__ import annotations

import errno
import json
import os
import shutil
import tempfile
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from omnisort_hw.errors import CalibrationFileError, OmnisortError, StorageError

HISTORY_DIRNAME = "history"


def os_error_text(exc: OSError) -> str:
    """`[Errno 28] ENOSPC: No space left on device (PATH)` from an OSError."""
    name = errno.errorcode.get(exc.errno or 0, "")
    text = exc.strerror or str(exc)
    where = f" ({exc.filename})" if exc.filename else ""
    return f"[Errno {exc.errno}] {name}: {text}{where}" if exc.errno else f"{text}{where}"


def read_input_bytes(
    path: str | os.PathLike[str], noun: str, error: type[OmnisortError], missing: str
) -> bytes:
    """The bytes of a file the user named, or `error` naming it: a folder ("is a folder, not
    a(n) `noun`"), missing (`missing`), unreadable, or empty (0 bytes, or blank)."""
    p = Path(path)
    if p.is_dir():
        raise error(f"{p}: is a folder, not {noun}")
    if not p.is_file():
        raise error(f"{p}: {missing}")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise error(f"{p}: cannot be read ({os_error_text(exc)})") from None
    if not data.strip():
        raise error(f"{p}: the file is empty ({len(data)} bytes); copy it again")
    return data


def read_calibration_json(path: str | os.PathLike[str], what: str) -> dict[str, Any]:
    """The JSON object in the calibration file `path` (`what`: "camera", "system"), or a
    CalibrationFileError naming the file: missing, a folder, empty, unreadable, not JSON (an
    image given as a calibration), or not an object."""
    p = Path(path)
    noun = f"{what} calibration file"
    data = read_input_bytes(p, f"a {noun}", CalibrationFileError, f"{noun} not found")
    try:
        obj = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise CalibrationFileError(
            f"{p}: corrupt, not a readable JSON {what} calibration ({exc})"
        ) from None
    if not isinstance(obj, dict):
        raise CalibrationFileError(f"{p}: corrupt, top level is not a JSON object")
    return obj


def check_writable(directory: str | os.PathLike[str], what: str) -> Path:
    """Create `directory` if needed and prove a file can be written, synced and removed in it;
    StorageError names the directory and the OS error otherwise."""
    folder = Path(directory)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        write_temp(folder, "writable-check", b"ok\n").unlink()
    except OSError as exc:
        raise StorageError(f"{what} {folder} is not writable: {os_error_text(exc)}") from None
    return folder


def _creation_problem(target: Path) -> str | None:
    """Why `target` (which does not exist) cannot be created: its nearest existing ancestor
    is not a folder, or not writable."""
    ancestor = target.parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        return f"{ancestor} is not a folder, so {target} cannot be created"
    problem = _write_problem(ancestor)
    return f"{problem}, so {target} cannot be created" if problem else None


def _write_problem(folder: Path) -> str | None:
    """Why no file can be created in the existing `folder`, found by creating (and removing)
    an empty one: permission bits say nothing for root, nor for /proc, a read-only mount or a
    full disk."""
    try:
        write_temp(folder, "write-check", b"").unlink()
    except OSError as exc:
        return f"{folder} is not writable ({os_error_text(exc)})"
    return None


def output_file_problem(path: str | os.PathLike[str]) -> str | None:
    """Why a file cannot be written at `path`, or None: checked before long work starts, so a
    calibration does not run for minutes and then fail on its output name."""
    target = Path(path)
    if target.is_dir():
        return f"{target} is a folder; give a file name inside it"
    if target.exists():
        return _write_problem(target.parent)
    return _creation_problem(target)


def output_folder_problem(path: str | os.PathLike[str]) -> str | None:
    """Why files cannot be written into the folder `path` (created if missing), or None."""
    target = Path(path)
    if not target.exists():
        return _creation_problem(target)
    if not target.is_dir():
        return f"{target} is a file, not a folder"
    return _write_problem(target)


def _fsync_dir(directory: Path) -> None:
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def history_dir(path: str | os.PathLike[str]) -> Path:
    """The folder beside `path` where previous versions of it are kept."""
    return Path(path).parent / HISTORY_DIRNAME


def history_versions(path: str | os.PathLike[str]) -> list[Path]:
    """Previous versions of `path`, oldest first (names sort by their UTC timestamp)."""
    target = Path(path)
    folder = history_dir(target)
    if not folder.is_dir():
        return []
    prefix = f"{target.name}."
    return sorted(
        p for p in folder.iterdir() if p.name.startswith(prefix) and not p.name.endswith(".tmp")
    )


def prune_history(path: str | os.PathLike[str], keep: int) -> list[Path]:
    """Delete all but the newest `keep` previous versions of `path`; returns the deleted paths."""
    versions = history_versions(path)
    doomed = versions[: max(0, len(versions) - max(0, keep))]
    for old in doomed:
        old.unlink(missing_ok=True)
    return doomed


def _keep_previous(target: Path) -> Path | None:
    """Preserve the current `target` in the history folder before it is replaced; returns the
    new history entry (None when one with the same name exists already).

    A hard link is atomic and costs nothing (the rename below leaves the old inode to the link);
    where links are not supported the file is copied to a temp name, fsynced and renamed.
    """
    history = history_dir(target)
    history.mkdir(exist_ok=True)
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S.%fZ")
    dest = history / f"{target.name}.{stamp}"
    try:
        os.link(target, dest)
    except FileExistsError:
        return None
    except OSError:
        tmp = history / f".{dest.name}.tmp"
        try:
            shutil.copy2(target, tmp)
            with open(tmp, "rb") as handle:
                os.fsync(handle.fileno())
            os.replace(tmp, dest)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
    _fsync_dir(history)
    return dest


def write_temp(directory: Path, name: str, data: bytes) -> Path:
    """`data` in a new temp file `.NAME.*.tmp` of `directory`, fsynced (the one place where a
    write's bytes reach the disk: a full disk or a read-only folder fails here)."""
    fd, tmp_name = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise
    return Path(tmp_name)


def atomic_write_bytes(
    path: str | os.PathLike[str],
    data: bytes,
    keep_history: bool = True,
    history_keep: int | None = None,
) -> Path:
    """Write `data` to `path` so that readers see either the old or the new file, never half.

    With `keep_history`, an existing file is kept as `history/NAME.TIMESTAMP` beside it;
    `history_keep` then bounds how many previous versions stay (None: all). A write that fails
    leaves the file and its history exactly as they were: the new bytes are on disk before the
    history is touched, a history entry added for a rename that then fails is taken back, and
    old versions are pruned only after the new file is in place.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = write_temp(target.parent, target.name, data)
    added: Path | None = None
    try:
        if keep_history and target.exists():
            added = _keep_previous(target)
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        if added is not None:
            added.unlink(missing_ok=True)
        raise
    _fsync_dir(target.parent)
    if keep_history and history_keep is not None:
        prune_history(target, history_keep)
    return target


def atomic_write_json(
    path: str | os.PathLike[str],
    obj: object,
    keep_history: bool = True,
    history_keep: int | None = None,
) -> Path:
    """Serialise `obj` as indented JSON and write it atomically."""
    text = json.dumps(obj, indent=2, sort_keys=False) + "\n"
    return atomic_write_bytes(
        path, text.encode("utf-8"), keep_history=keep_history, history_keep=history_keep
    )


def remove_stale_temps(directory: str | os.PathLike[str]) -> list[Path]:
    """Delete temp files left by writes that were killed before their rename."""
    folder = Path(directory)
    if not folder.is_dir():
        return []
    stale = [p for p in folder.glob(".*.tmp") if p.is_file()]
    history = folder / HISTORY_DIRNAME
    if history.is_dir():
        stale += [p for p in history.glob(".*.tmp") if p.is_file()]
    for p in stale:
        p.unlink(missing_ok=True)
    return stale
