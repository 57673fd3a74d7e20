"""A run directory belongs to one study: refuse to mix the results of two configs.

Each stage's tables depend on some config sections; a command whose sections
differ from the run's recorded ``config.yaml`` is refused, naming the first
differing key, unless ``--force`` redoes that stage (and drops what depended on it).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hcid import results, tables
from hcid.config import Config
from hcid.errors import DataError

__all__ = ["IDENTIFICATION_SECTIONS", "SIMULATION_SECTIONS", "check_run_dir", "record_config"]

#: Config sections each stage's tables depend on.
SIMULATION_SECTIONS = ("models", "loop", "signals", "timing", "seeds")
IDENTIFICATION_SECTIONS = (*SIMULATION_SECTIONS, "identify", "data")


def _identification_files() -> list[str]:
    """The tables identification and later stages write (stale when ``identify`` changes)."""
    from hcid.methods import METHODS

    files = [tables.FRONTIER.file, tables.IDENTIFY_LOG.file, tables.SELECTION.file, tables.BREAKPOINTS.file]
    files += [tables.thresholds().file, tables.CALIBRATION.file, tables.MEASURED.file]
    files += [tables.stage_choice(s.name, s.inputs).file for m in METHODS.values() for s in m.choice_stages]
    return files


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
    import yaml

    if run_dir.exists() and not run_dir.is_dir():
        raise DataError(f"{run_dir}: not a directory; choose another --run")
    path = run_dir / "config.yaml"
    if not path.is_file():
        return
    try:
        previous = yaml.safe_load(path.read_text())
        if not isinstance(previous, dict):
            raise TypeError
    except (yaml.YAMLError, OSError, TypeError) as exc:
        raise DataError(
            f"{path}: not a readable config; remove the run directory or use another --run"
        ) from exc
    current = yaml.safe_load(config.to_yaml())
    if stage == "simulate":
        sections, stale, redo = SIMULATION_SECTIONS, None, "hcid simulate --force"
    elif stage == "identify":
        sim_key = _first_difference(
            {k: previous.get(k) for k in SIMULATION_SECTIONS},
            {k: current.get(k) for k in SIMULATION_SECTIONS},
        )
        if sim_key is not None:
            raise DataError(
                f"{run_dir}: simulated with another config ({sim_key} differs); "
                "use `hcid simulate --force` to redo it or --run for another directory"
            )
        sections, stale, redo = IDENTIFICATION_SECTIONS, _identification_files(), "hcid identify --force"
    else:
        sections, stale, redo = IDENTIFICATION_SECTIONS, None, "hcid identify --force"
    key = _first_difference({k: previous.get(k) for k in sections}, {k: current.get(k) for k in sections})
    if key is None:
        return
    if not force:
        raise DataError(
            f"{run_dir}: made with another config ({key} differs); use `{redo}` to redo it "
            "or --run for another directory"
        )
    files = run_dir.glob("*.parquet") if stale is None else (run_dir / name for name in stale)
    for table in files:
        table.unlink(missing_ok=True)
    results.clear_parts(run_dir)


def record_config(config: Config, run_dir: Path) -> None:
    """Write the resolved config as the run's ``config.yaml`` (atomically)."""
    results.write_text(config.to_yaml(), run_dir / "config.yaml")
