"""Output folders hcid owns: every folder it writes (a run directory, a report folder) follows these rules.

- A folder hcid writes into is new, empty, or marked as hcid's by a manifest
  (:data:`MANIFEST`) written before anything else; the manifest names the
  folder's kind (``run directory``, ``report``) and every file hcid wrote there.
- ``/``, the working directory and its parents are never used as an output folder.
- hcid replaces and deletes only the files its manifest lists; a file of the
  same name that it did not write is never touched (the write is refused).
- Every file is written to a temporary file beside it and renamed over it, so a
  reader never sees a half-written file and a failed write leaves the old one.

Part of the results layer: the only module that creates output folders.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

from hcid.errors import DataError

__all__ = [
    "MANIFEST",
    "atomic_write",
    "check_replaceable",
    "check_output_path",
    "claim",
    "owned_files",
    "remove_owned",
]

#: The mark of an hcid folder: written first, it lists every file hcid wrote there (and only
#: those are ever replaced or deleted by hcid).
MANIFEST = "hcid-run.json"
RUN_DIRECTORY = "run directory"
REPORT = "report"


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _current_umask()


def check_output_path(folder: Path, what: str) -> Path:
    """``folder`` resolved, if it can be an output folder of its own.

    Raises
    ------
    DataError
        For ``/``, the working directory or one of its parents, or a path that is
        not a directory.
    """
    try:
        resolved = folder.resolve()
        cwd = Path.cwd().resolve()
    except (OSError, RuntimeError) as exc:
        raise DataError(f"{folder}: not a usable {what} ({exc})") from exc
    if resolved == resolved.parent or resolved == cwd or resolved in cwd.parents:
        raise DataError(
            f"{folder}: refusing to use it as a {what} (it is / , the working directory or one "
            "of its parents); choose a folder of its own"
        )
    if folder.exists() and not folder.is_dir():
        raise DataError(f"{folder}: not a directory; choose another {what}")
    return resolved


def _manifest_kind(folder: Path) -> str | None:
    try:
        data = json.loads((folder / MANIFEST).read_text())
        return data.get("hcid") if isinstance(data, dict) else None
    except (OSError, ValueError):
        return None


def check_replaceable(path: Path) -> None:
    """Refuse ``path`` if it exists in an hcid folder without being one of hcid's files.

    Raises
    ------
    DataError
        Naming the file.
    """
    foreign = path.name != MANIFEST and path.exists() and (path.parent / MANIFEST).is_file()
    if foreign and path.name not in owned_files(path.parent):
        raise DataError(f"{path}: not written by hcid; refusing to replace it")


def atomic_write(path: Path, write: Callable[[str], object]) -> None:
    """Write ``path`` through ``write(temporary_path)`` and a rename; refuse a file hcid did not write.

    In an hcid folder the file is listed in the mark before it is renamed into place.

    Raises
    ------
    DataError
        If ``path`` exists in an hcid folder without being one of its files, or the
        write fails (the previous file is then intact).
    """
    check_replaceable(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise DataError(f"{path}: cannot write ({exc.strerror or exc})") from exc
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)
        _register(path)  # listed before it appears: a kill in between leaves no file hcid disowns
        os.replace(tmp, path)
    except OSError as exc:  # a full disk, a quota: one line, the previous file intact
        Path(tmp).unlink(missing_ok=True)
        raise DataError(f"{path}: cannot write ({exc.strerror or exc}); the previous file is intact") from exc
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _register(path: Path) -> None:
    """List ``path`` in its folder's manifest when the folder is an hcid folder."""
    folder = path.parent
    if path.name == MANIFEST or not (folder / MANIFEST).is_file():
        return
    files = owned_files(folder)
    if path.name not in files:
        _write_manifest(folder, [*files, path.name], _manifest_kind(folder) or RUN_DIRECTORY)


def _write_manifest(folder: Path, files: Sequence[str], kind: str) -> None:
    text = json.dumps({"hcid": kind, "version": 1, "files": sorted(set(files))}, indent=1)
    atomic_write(folder / MANIFEST, lambda tmp: Path(tmp).write_text(text + "\n"))


def owned_files(folder: Path) -> list[str]:
    """The files hcid wrote in ``folder`` (its manifest), or [] if it has none or it is damaged."""
    try:
        data = json.loads((Path(folder) / MANIFEST).read_text())
        files = data["files"]
        return [f for f in files if isinstance(f, str) and f and "/" not in f and f not in (".", "..")]
    except (OSError, ValueError, KeyError, TypeError):
        return []


def claim(
    folder: Path,
    known: Sequence[str],
    kind: str = RUN_DIRECTORY,
    adopt: Callable[[list[str]], bool] | None = None,
    advice: str = "choose a new or empty folder",
) -> None:
    """Make ``folder`` an hcid folder of ``kind``, or check that it is one.

    A new or empty folder gets a manifest. A folder written by an hcid without
    manifests is adopted when ``adopt(entries)`` says so (its files among
    ``known`` become hcid's); any other non-empty folder is refused (the error
    ends with ``advice``), as is an hcid folder of another kind.

    Raises
    ------
    DataError
        For a folder hcid does not own.
    """
    folder = Path(folder)
    if (folder / MANIFEST).is_file():
        found = _manifest_kind(folder)
        if found != kind:
            what = f"an hcid {found}" if found in (RUN_DIRECTORY, REPORT) else f"its {MANIFEST} is not hcid's"
            raise DataError(f"{folder}: {what}, not an hcid {kind}; choose another folder")
        return
    try:
        entries = sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []
    except OSError as exc:
        raise DataError(f"{folder}: cannot read ({exc.strerror or exc})") from exc
    if entries and not (adopt is not None and adopt(entries)):
        raise DataError(f"{folder}: not an hcid {kind} (no {MANIFEST}, and it holds other files); {advice}")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(f"{folder}: cannot create ({exc.strerror or exc})") from exc
    _write_manifest(folder, [e for e in entries if e in known], kind)


def remove_owned(folder: Path, names: Sequence[str] | None = None) -> None:
    """Delete the files hcid wrote in ``folder`` (only those named, if ``names``)."""
    owned = owned_files(folder)
    keep = [f for f in owned if names is not None and f not in names]
    for name in owned:
        if name not in keep:
            (Path(folder) / name).unlink(missing_ok=True)
    _write_manifest(Path(folder), keep, _manifest_kind(Path(folder)) or RUN_DIRECTORY)
