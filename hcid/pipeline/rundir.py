"""Run directories: one study each, one command at a time, and hcid deletes only what it wrote.

- :func:`using` holds a run directory for a command: it refuses paths that are
  not a plain directory of their own (``/``, the working directory or one of its
  parents), marks the directory as hcid's with a manifest written first
  (:func:`hcid.io.folders.claim`), and takes an ``fcntl`` lock that the operating
  system releases when the process ends, so a ``kill -9`` never leaves a stale
  lock; a second command on the directory is refused in one line naming the
  process that holds it.
- :func:`check_run_dir`: each stage's tables depend on some config sections; a
  command whose sections differ from the run's recorded ``config.yaml`` is
  refused, naming the first differing key, unless ``--force`` redoes that stage
  (and drops, of the files hcid wrote, those that depended on it).
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import yaml

from hcid import tables
from hcid.assembly.resolve import read_yaml
from hcid.config import Config
from hcid.errors import ConfigError, DataError, HcidError
from hcid.io import folders, results
from hcid.methods import METHODS

__all__ = [
    "IDENTIFICATION_SECTIONS",
    "LOCK",
    "SIMULATION_SECTIONS",
    "check_run_dir",
    "holds_run_dir",
    "known_files",
    "record_config",
    "using",
]

LOCK = ".hcid.lock"
_HELD: dict[Path, list] = {}  # run directory -> [open lock file, depth] held by this process


def _forget_held() -> None:
    """In a forked worker: close its copies of the lock files, which stay the parent's alone."""
    for handle, _ in _HELD.values():
        handle.close()
    _HELD.clear()


os.register_at_fork(after_in_child=_forget_held)


def known_files() -> list[str]:
    """Every file name hcid writes in a run directory."""
    schemas = [
        tables.SIMULATIONS,
        tables.SIMULATION_SUMMARY,
        tables.MEASURED,
        tables.RUNS,
        tables.FRONTIER,
        tables.IDENTIFY_LOG,
        tables.SELECTION,
        tables.BREAKPOINTS,
        tables.thresholds(),
        tables.CALIBRATION,
        tables.RUN_LOG,
        tables.HC_PARAMETERS,
        tables.RESIDUALS,
        tables.HC_LOOP,
        tables.REMNANT_SPECTRUM,
        tables.ANALYSIS,
        tables.ANALYSIS_GROUPS,
        tables.FC_ESTIMATES,
        tables.RATES,
        tables.HANDOFF,
    ]
    files = [s.file for s in schemas] + ["config.yaml", folders.MANIFEST, LOCK, "analysis.csv", "forcing.csv"]
    files += [tables.stage_choice(s.name, s.inputs).file for m in METHODS.values() for s in m.choice_stages]
    return files


def holds_run_dir(*, create: bool = True):
    """Decorate ``func(config, run_dir, ...)`` to run while holding ``run_dir`` (:func:`using`)."""

    def decorate(func):
        @functools.wraps(func)
        def wrapper(config, run_dir, *args, **kwargs):
            with using(Path(run_dir), create=create):
                return func(config, Path(run_dir), *args, **kwargs)

        return wrapper

    return decorate


@contextlib.contextmanager
def using(run_dir: Path, *, create: bool = True) -> Iterator[Path]:
    """Hold ``run_dir`` for one command: checked, claimed and locked (re-entrant in a process).

    With ``create`` False a missing directory is an error instead of a new run.

    Raises
    ------
    DataError
        If the path is not a directory of its own, hcid does not own it, or
        another process holds it.
    """
    resolved = folders.check_output_path(run_dir, "run directory")
    if not create and not run_dir.is_dir():
        raise DataError(
            f"{run_dir}: missing; make it first with `hcid run CONFIG` (a simulated study) or "
            "`hcid analyse CONFIG --data DATA` (measured data)"
        )
    held = _HELD.get(resolved)
    created = not run_dir.exists()
    claimed = not (run_dir / folders.MANIFEST).is_file()  # new or empty: this command claims it
    if held is not None:
        held[1] += 1
        try:
            yield run_dir
        finally:
            held[1] -= 1
        return
    known = known_files()
    advice = (
        "choose a new or empty folder" if create else "give a run directory `hcid run` or `hcid analyse` made"
    )

    def claim() -> None:  # a folder holding only a lock file is empty: a command left it so
        adopt = lambda entries: set(entries) <= {LOCK} or _written_by_hcid(entries, known)  # noqa: E731
        folders.claim(run_dir, known, adopt=adopt, advice=advice)

    claim()
    lock_path = run_dir / LOCK
    lock_before = lock_path.stat() if lock_path.is_file() else None
    try:
        handle = _locked(run_dir, lock_path)
    except _ReadOnly:  # nobody can write it, reading is safe
        yield run_dir
        return
    claim()  # again, locked: a command that held it may have left it empty since
    handle.seek(0)
    holder_before = handle.read()
    handle.seek(0)
    handle.truncate()
    handle.write(f"hcid pid {os.getpid()} ({' '.join(os.path.basename(a) for a in sys.argv[:2])})")
    handle.flush()
    _HELD[resolved] = [handle, 1]
    try:
        yield run_dir
    except HcidError:
        # A refused command leaves the directory as it found it, its lock file included.
        _restore_lock(handle, lock_path, holder_before, lock_before)
        raise
    finally:
        del _HELD[resolved]
        if claimed:  # while still locked: a command arriving now finds the lock file gone
            _remove_if_unused(run_dir, remove_folder=created)
        handle.close()  # releases the lock


class _ReadOnly(Exception):
    """The run directory cannot be locked because nobody can write it."""


def _locked(run_dir: Path, lock_path: Path):
    """The lock file, opened and exclusively locked. A lock taken on a file that is no longer at
    ``lock_path`` (a command that held it removed it, leaving the folder as it found it) holds
    nothing: the file is opened again.

    Raises
    ------
    DataError
        If another process holds the lock, or the lock file cannot be opened.
    """
    for _ in range(5):
        try:
            handle = open(lock_path, "a+")  # noqa: SIM115 (held until the command ends)
        except OSError as exc:
            if not os.access(run_dir, os.W_OK):
                raise _ReadOnly from exc
            raise DataError(f"{run_dir}: cannot lock ({exc.strerror or exc})") from exc
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.seek(0)
            holder = handle.read(200).strip() or "another process"
            handle.close()
            raise DataError(
                f"{run_dir}: in use by {holder}; wait for it to finish or choose another --run"
            ) from None
        try:
            if os.stat(lock_path).st_ino == os.fstat(handle.fileno()).st_ino:
                return handle
        except FileNotFoundError:
            pass
        handle.close()
    raise DataError(f"{run_dir}: in use (its lock file keeps being replaced); choose another --run")


def _restore_lock(handle, path: Path, text: str, before: os.stat_result | None) -> None:
    try:
        if before is None:
            path.unlink(missing_ok=True)
            return
        handle.seek(0)
        handle.truncate()
        handle.write(text)
        handle.flush()
        os.utime(path, ns=(before.st_atime_ns, before.st_mtime_ns))
    except OSError:
        pass


def _written_by_hcid(entries: list[str], known: list[str]) -> bool:
    """A run directory of an hcid without manifests: a config.yaml, a table, and only hcid's files.

    A folder with a config.yaml and nothing of hcid's is a user's (their config beside it)."""
    tables_ = [e for e in entries if e.endswith(".parquet")]
    return (
        "config.yaml" in entries and bool(tables_) and set(entries) <= {*known, results.PARTS, "report", LOCK}
    )


def _remove_if_unused(run_dir: Path, *, remove_folder: bool) -> None:
    """A directory this command claimed and then wrote nothing into (a refusal) is left as it was:
    its manifest and lock removed, and the directory itself where the command created it."""
    try:
        if {p.name for p in run_dir.iterdir()} <= {folders.MANIFEST, LOCK}:
            for name in (folders.MANIFEST, LOCK):
                (run_dir / name).unlink(missing_ok=True)
            if remove_folder:
                run_dir.rmdir()
    except OSError:
        pass


#: Config sections each stage's tables depend on.
SIMULATION_SECTIONS = ("models", "loop", "signals", "timing", "seeds")
#: The measured data's own settings first: the identify grids and timing follow from them, and
#: a refusal names the key the user changed (data.analysis_rate, not a grid it moved).
IDENTIFICATION_SECTIONS = ("data", *SIMULATION_SECTIONS, "identify")


def _identification_files() -> list[str]:
    """The tables identification and later stages write (stale when ``identify`` changes)."""
    simulation = {tables.SIMULATIONS.file, tables.SIMULATION_SUMMARY.file, tables.RUN_LOG.file}
    return [f for f in known_files() if f.endswith(".parquet") and f not in simulation]


def _first_difference(a: Any, b: Any, path: str = "") -> str | None:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in list(a) + [k for k in b if k not in a]:
            where = f"{path}.{key}" if path else str(key)
            if key not in a or key not in b:
                return where
            found = _first_difference(a[key], b[key], where)
            if found:
                return found
        return None
    return None if a == b else (path or "<top>")


def check_run_dir(config: Config, run_dir: Path, stage: str, *, force: bool = False) -> None:
    """Refuse to mix results of two configs in one run directory.

    ``stage`` is 'simulate', 'identify' or 'select'. If ``run_dir/config.yaml``
    differs from ``config`` in a section the stage's inputs depend on, raise
    :class:`DataError` naming the first differing key, unless ``force``: then
    the tables made from the old sections are removed (simulate: every table;
    identify: identification and later). A difference only in later sections
    (e.g. the W grid for a sweep) is fine; the stage's caller records the new
    config when it writes.
    """
    if run_dir.exists() and not run_dir.is_dir():
        raise DataError(f"{run_dir}: not a directory; choose another --run")
    path = run_dir / "config.yaml"
    if not path.is_file():
        return
    try:
        previous = read_yaml(path, "run config")
        if not isinstance(previous, dict):
            raise ConfigError(f"{path}: not a mapping")
    except ConfigError as exc:
        raise DataError(f"{exc}; remove the run directory or use another --run") from exc
    current = _common_stages(_own_yaml(config.to_yaml()), previous)
    previous = _common_stages(previous, current)
    if stage == "simulate":
        sections, stale, redo = SIMULATION_SECTIONS, None, "`hcid simulate --force`"
    elif stage == "identify":
        # Between two measured studies (neither simulates) the plant (loop) is an analysis input,
        # named below; a simulation in either is never mixed with another study's results.
        sim_key = _first_difference(
            {k: previous.get(k) for k in SIMULATION_SECTIONS},
            {k: current.get(k) for k in SIMULATION_SECTIONS},
        )
        if sim_key is not None and (config.simulates or "models" in previous):
            raise DataError(
                f"{run_dir}: simulated with another config ({sim_key} differs); "
                "use `hcid simulate --force` to redo it or --run for another directory"
            )
        sections, stale = IDENTIFICATION_SECTIONS, _identification_files()
        redo = "`hcid identify --force` (`hcid analyse --force` for measured data)"
    else:
        sections, stale, redo = IDENTIFICATION_SECTIONS, None, "`hcid identify --force`"
    key = _first_difference({k: previous.get(k) for k in sections}, {k: current.get(k) for k in sections})
    if key is None:
        return
    if not force:
        raise DataError(
            f"{run_dir}: made with another config ({key} differs); redo it with {redo} "
            "or choose another --run"
        )
    owned = folders.owned_files(run_dir)
    folders.remove_owned(
        run_dir, [f for f in owned if f.endswith(".parquet") and (stale is None or f in stale)]
    )
    results.clear_parts(run_dir)


def _own_yaml(text: str) -> Any:
    """YAML that hcid dumped itself, read back by libyaml where PyYAML has it (the same objects
    as ``yaml.safe_load``, several times faster); a file on disk goes through ``read_yaml``."""
    return yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))  # noqa: S506 (safe)


def _common_stages(data: Any, other: Any) -> Any:
    """``data`` with only the identify stages ``other`` also holds.

    A stage of a method a command did not resolve (or that a run was made
    without, say a method registered since) is no difference between two configs.
    """
    if not isinstance(data, dict) or not isinstance(data.get("identify"), dict):
        return data
    theirs = other.get("identify") if isinstance(other, dict) else None
    theirs = theirs if isinstance(theirs, dict) else {}
    section = {k: v for k, v in data["identify"].items() if k == "target_shift" or k in theirs}
    return {**data, "identify": section}


def record_config(config: Config, run_dir: Path) -> None:
    """Write the resolved config as the run's ``config.yaml`` (atomically).

    Stages recorded earlier and not resolved by this command stay recorded while
    the directory holds identification results (``frontier.parquet``): the record
    holds the stages of every method whose results are there.
    """
    text = config.to_yaml()
    path = run_dir / "config.yaml"
    if path.is_file() and (run_dir / tables.FRONTIER.file).is_file():
        try:
            previous = read_yaml(path, "run config")
        except ConfigError:
            previous = None
        earlier = previous.get("identify") if isinstance(previous, dict) else None
        if isinstance(earlier, dict):
            current = _own_yaml(text)
            kept = {k: v for k, v in earlier.items() if k not in current["identify"]}
            if kept:
                current["identify"] = {**current["identify"], **kept}
                text = yaml.safe_dump(current, sort_keys=False)
    results.write_text(text, path)
