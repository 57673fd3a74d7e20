"""Resolve a described config: read what it names, check what needs other layers.

:func:`hcid.config.parse.describe_config` turns YAML into dataclasses and checks
values; this step, above the data readers and the method registry, completes a
:class:`~hcid.config.Config` for a command:

- forcing functions of kind ``file`` are read (:func:`hcid.io.measured.read_signal`,
  the checks every signal from a file passes) and checked against the window;
- the stages of the methods the command uses, and only those, are built
  (:func:`hcid.config.stages.build_stages` with each method's stage specs): a
  method added to the registry changes no other config or run directory;
- the selection criteria are looked up in :mod:`hcid.selection.criteria`;
- a simulating config's closed loops must be stable (:func:`hcid.loop.hcmodel.check_closed_loops`)
  and its study not too large.

:func:`load_config` reads a YAML file (:func:`read_yaml`: bounded, no aliases) and does both.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hcid import methods
from hcid.config import Config, FileSignal, HCModel, IdentifyConfig
from hcid.config._checks import LIMITS
from hcid.config.forcing import check_forcing_values
from hcid.config.parse import default_data, describe_config
from hcid.config.stages import build_stages, parse_identify, stage_raw
from hcid.errors import ConfigError, DataError, checked_rate, quote
from hcid.io.datasets import DataSet
from hcid.io.measured import FileAtRate, read_signal, resampling_factors, samples_needed
from hcid.loop.hcmodel import check_closed_loops
from hcid.selection import criteria

__all__ = [
    "describe_file",
    "load_config",
    "methods_of_run",
    "parse_config",
    "read_study",
    "with_data",
    "read_yaml",
    "recorded_methods",
    "resolve_config",
    "resolve_identify",
]


def _stage_specs(method_names: Sequence[str] | None) -> dict[str, Any]:
    chosen = methods.METHODS if method_names is None else {n: methods.get(n) for n in method_names}
    return {spec.name: spec for m in chosen.values() for spec in m.stages}


def _check_stage_names(identify: IdentifyConfig) -> None:
    known = methods.stage_specs()
    for name, _ in identify.sections:
        if name not in known:
            allowed = ", ".join(sorted(["target_shift", "windows_in", *known]))
            raise ConfigError(f"identify.{name}: unknown key (allowed: {allowed})")


def _read_forcing(name: str, spec: Any, timing) -> Any:
    """A file's forcing function with its values: read from the file, unless already given
    (the twins of ``hcid analyse``, built in memory from a run's record)."""
    if not isinstance(spec, FileSignal):
        return spec
    if spec.values is None:
        try:
            values = read_signal(spec.path, spec.column, spec.run, spec.run_column)
        except DataError as exc:
            raise ConfigError(f"signals.{name}: {exc}") from None
        spec = dataclasses.replace(spec, values=values)
    check_forcing_values(name, spec, timing)
    return spec


def _selection(config: Config) -> tuple[Any, dict]:
    chosen = []
    for name, constants in config.selection.criteria:
        built = criteria.build(name, dict(constants))
        chosen.append((built.name, built.constants))
    raw = {**config.raw["selection"], "criteria": {n: dict(c) for n, c in chosen}}
    return dataclasses.replace(config.selection, criteria=tuple(chosen)), raw


def resolve_config(config: Config, method_names: Sequence[str] | None = None) -> Config:
    """Complete a described config for a command that uses ``method_names`` (None: every registered one).

    Raises
    ------
    ConfigError
        Naming the key: an unreadable or unusable forcing file, a stage section of
        no registered method, a stage that does not fit the record, an unknown
        criterion, an unstable closed loop or a study too large.
    """
    _check_stage_names(config.identify)
    disturbance = _read_forcing("disturbance", config.disturbance, config.timing)
    target = _read_forcing("target", config.target, config.timing)
    identify = build_stages(config.identify, _stage_specs(method_names), config.timing)
    selection, selection_raw = _selection(config)
    _check_study_size(identify, config.seeds, config.models)
    if config.simulates:
        check_closed_loops(config.models, config.loop, config.timing.sim_dt)
    # The resolved config (a run's config.yaml) holds the stages built, windows in samples.
    raw = dict(config.raw)
    raw["identify"] = {
        "target_shift": identify.target_shift,
        **{name: stage_raw(stage) for name, stage in identify.stages},
    }
    raw["selection"] = selection_raw
    return dataclasses.replace(
        config, disturbance=disturbance, target=target, identify=identify, selection=selection, raw=raw
    )


def resolve_identify(
    data: Any, rate: float, n_samples: int, method_names: Sequence[str] | None = None
) -> IdentifyConfig:
    """An ``identify`` section alone (None: the defaults), resolved for ``n_samples`` at ``rate`` Hz."""
    identify, timing = parse_identify(data, rate, n_samples)
    _check_stage_names(identify)
    return build_stages(identify, _stage_specs(method_names), timing)


def recorded_methods(data: Any) -> tuple[str, ...]:
    """The registered methods whose every stage a resolved config's ``identify`` section holds.

    A run's ``config.yaml`` records the stages of the methods run in it, so these
    are the methods a run directory's tables can hold.
    """
    section = data.get("identify") if isinstance(data, dict) else None
    if not isinstance(section, dict):
        return ()
    return tuple(n for n, m in methods.METHODS.items() if all(st.name in section for st in m.stages))


def methods_of_run(run_dir: Path) -> tuple[str, ...] | None:
    """The methods a run directory's ``config.yaml`` records (:func:`recorded_methods`), None without one."""
    path = Path(run_dir) / "config.yaml"
    if not path.is_file():
        return None
    try:
        return recorded_methods(read_yaml(path, "run config"))
    except ConfigError:
        return None


def parse_config(
    data: Any,
    name: str,
    base: Path | None = None,
    method_names: Sequence[str] | None = None,
    *,
    forcing: dict[str, np.ndarray] | None = None,
) -> Config:
    """:func:`~hcid.config.parse.describe_config` then :func:`resolve_config`. ``forcing``: the
    values of the file forcing functions by signal (``target``, ``disturbance``), given in
    memory instead of read from their files (which hold the same values)."""
    config = describe_config(data, name, base)
    for signal, values in (forcing or {}).items():
        spec = getattr(config, signal)
        given = np.ascontiguousarray(values, dtype=np.float64)
        config = dataclasses.replace(config, **{signal: dataclasses.replace(spec, values=given)})
    return resolve_config(config, method_names)


def described_name(path: str | Path) -> str:
    """The study's name as a config gives it (its ``name`` key, else the file's stem)."""
    path = Path(path)
    raw = read_yaml(path)
    name = raw.get("name") if isinstance(raw, dict) else None
    return name if isinstance(name, str) and name else path.stem


def describe_file(path: str | Path, run_dir: Path | None = None) -> Config:
    """Read a YAML study config and describe it (:func:`~hcid.config.parse.describe_config`), unresolved.

    A measured study that leaves ``data.analysis_rate`` or ``data.window`` out takes them from
    the run directory's recorded config (a command after ``hcid identify --data`` or ``hcid
    analyse``; with the data themselves, :func:`read_study`).
    """
    path = Path(path)
    raw = read_yaml(path)
    if _needs_timing(raw):
        recorded = (run_dir / "config.yaml") if run_dir is not None else None
        if recorded is None or not recorded.is_file():
            raise ConfigError(
                "data.analysis_rate, data.window: missing; give them, or let `hcid identify --data` "
                "or `hcid analyse` take them from the data first"
            )
        earlier = read_yaml(recorded, "run config").get("data", {})
        raw = {
            **raw,
            "data": {**raw["data"], **{k: earlier[k] for k in ("analysis_rate", "window") if k in earlier}},
        }
    return describe_config(raw, path.stem, path.parent)


def read_study(
    path: str | Path | Mapping[str, Any],
    sources: Sequence[str | Path],
    method_names: Sequence[str] | None = None,
    *,
    skip_unreadable: bool = False,
    single_input: bool = False,
) -> tuple[Config, DataSet]:
    """A measured study's config (YAML at ``path``, or the mapping such a file holds: its
    relative paths then from the working folder, its name ``name`` or ``study``), completed from
    its data where it leaves the analysis rate or window out (:func:`data_timing`) and resolved
    for ``method_names``, and its data set at the analysis rate: every file of ``sources`` found
    once and read once (:func:`hcid.io.datasets.read_files`, :func:`hcid.io.datasets.set_at`).
    With ``skip_unreadable``, files that cannot be read or fail their checks are set aside with
    their reasons (``DataSet.set_aside``) instead of refused; with ``single_input``, a run
    whose ft or fd is constant (a single-input trial) is kept, not refused.

    Raises
    ------
    ConfigError, DataError
        For a bad config, data section or data set, in one line.
    """
    from hcid.io.datasets import find_files, read_files, set_at

    if isinstance(path, Mapping):
        raw, path = _as_yaml(path), Path.cwd() / "study.yaml"
    else:
        path = Path(path)
        raw = read_yaml(path)
    if not isinstance(raw, dict) or not isinstance(raw.get("data", {}), dict):
        raise ConfigError(f"{path}: data: must be a mapping")
    reading = _reading(raw, path.parent)
    found = find_files(sources, reading.pattern, reading.exclude)
    files = found.files
    if _needs_timing(raw):  # the files taken to the analysis rate as read, then the window from them
        try:
            rate = checked_rate(raw["data"].get("analysis_rate"))
        except ConfigError:  # none given (or a bad one, which the config's own checks name)
            rate = analysis_rate
        read, aside = read_files(files, reading, rate, skip_unreadable)
        described = describe_config(data_timing(raw, [file for _, file, _ in read]), path.stem, path.parent)
    else:
        described = describe_config(raw, path.stem, path.parent)
        read, aside = read_files(files, reading, described.timing.output_rate, skip_unreadable)
    config = with_data(resolve_config(described, method_names))
    order = [str(f.path) for f in files]
    need = samples_needed(config)
    data_set = set_at(read, config.data, need, skip_unreadable, aside, order, found.skipped, single_input)
    return config, data_set


def _as_yaml(config: Mapping[str, Any]) -> dict:
    """A config given as a mapping, as its YAML file would read: string keys, and plain numbers,
    strings, booleans, None, lists and mappings as values (copied).

    Raises
    ------
    ConfigError
        Naming the first key whose value no YAML file could hold (a numpy number, a tuple, ...).
    """

    def plain(value: Any, where: str) -> Any:
        if isinstance(value, Mapping):
            bad = next((k for k in value if not isinstance(k, str)), None)
            if bad is not None:
                raise ConfigError(f"{where or 'config'}: keys must be strings, got {bad!r}")
            return {k: plain(v, f"{where}.{k}" if where else k) for k, v in value.items()}
        if isinstance(value, list):
            return [plain(v, f"{where}[{i}]") for i, v in enumerate(value)]
        if value is None or type(value) in (bool, int, float, str):
            return value
        raise ConfigError(
            f"{where or 'config'}: must be a number, string, boolean, list or mapping, as in a YAML "
            f"file; got a {type(value).__name__} ({value!r})"
        )

    return plain(config, "")


def with_data(config: Config) -> Config:
    """A config that reads measured data, its data section completed: the default column names
    (:func:`~hcid.config.parse.default_data`) where it has none (a simulation config given
    ``--data``). Its raw YAML, what a run directory records, stays as it was."""
    return config if config.data is not None else dataclasses.replace(config, data=default_data())


#: The analysis rate a measured study defaults to when its data are faster (Hz): SPEC 3's.
DEFAULT_ANALYSIS_RATE = 25.0
_SIMULATING = ("models", "signals", "seeds")


def _needs_timing(raw: Any) -> bool:
    """Whether a measured study's config leaves its analysis rate or window to the data."""
    if not isinstance(raw, dict) or "data" not in raw or "timing" in raw:
        return False
    if any(k in raw for k in _SIMULATING) or not isinstance(raw["data"], dict):
        return False
    return "analysis_rate" not in raw["data"] or "window" not in raw["data"]


def analysis_rate(native: float) -> float:
    """A measured study's default analysis rate for runs sampled at ``native`` Hz: their own if
    at most :data:`DEFAULT_ANALYSIS_RATE`, else that rate (25 Hz, SPEC 3's; or their own when
    25 Hz is no ratio p/q with p, q <= 100)."""
    rate = native if native <= DEFAULT_ANALYSIS_RATE else DEFAULT_ANALYSIS_RATE
    try:
        resampling_factors(native, rate)
    except DataError:
        rate = native
    return float(rate)


def data_timing(raw: dict, read: Sequence[FileAtRate]) -> dict:
    """``raw`` with the data section's ``analysis_rate`` and ``window`` taken from the files
    ``read`` at the analysis rate (:func:`hcid.io.measured.at_rate`) where the config leaves
    them out: the rate they were read at (:func:`analysis_rate`), and the shortest run after
    ``data.lead_in``, in whole samples.

    Raises
    ------
    DataError, ConfigError
        For a bad data set or data section, in one line.
    """
    data = dict(raw["data"])
    lead_in = data.get("lead_in", 0.0)
    rate = read[0].rate
    data.setdefault("analysis_rate", float(rate))
    if "window" not in data:
        shortest = min(len(s["ft"]) for f in read for s in f.signals.values())
        skip = round(float(lead_in) * rate)
        if shortest - skip < 2:
            where = read[0].path
            raise DataError(f"{where}: runs of {shortest} samples at {rate:g} Hz, none after the lead-in")
        data["window"] = (shortest - skip) / rate
    return {**raw, "data": data}


def _reading(raw: dict, base: Path | None):
    """The config's data section described on its own, at a placeholder timing, to read files."""
    data = dict(raw["data"]) if isinstance(raw.get("data"), dict) else {}
    probe = {k: v for k, v in raw.items() if k in ("name", "data")}
    probe["data"] = {**data, "analysis_rate": 1000.0, "window": 1.0, "lead_in": 0.0}  # whole samples
    probe["identify"] = {}  # the data section alone: no identification defaults at the placeholder rate
    return describe_config(probe, "probe", base).data


def load_config(path: str | Path, method_names: Sequence[str] | None = None) -> Config:
    """Read, check and resolve a YAML study config for the methods ``method_names`` (None: all).

    Raises
    ------
    ConfigError
        If the file is missing, is not YAML, or any key is wrong (naming it).
    """
    return resolve_config(describe_file(path), method_names)


def _check_study_size(identify: IdentifyConfig, seeds: tuple[int, ...], models: tuple[HCModel, ...]) -> None:
    per_record = sum(stage.grid.n_candidates for _, stage in identify.stages)
    total = per_record * len(seeds) * len(models)
    if total > LIMITS["study_candidates"]:
        raise ConfigError(
            f"identify: the study fits {total:,} candidates ({per_record:,} per record x "
            f"{len(seeds) * len(models):,} records), at most {LIMITS['study_candidates']:,} are allowed"
        )


class _Loader(yaml.SafeLoader):
    """yaml.SafeLoader without aliases (no expansion bombs), duplicate keys or deep nesting."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            mark = self.peek_event().start_mark
            raise ConfigError(f"line {mark.line + 1}: YAML aliases (*name) are not allowed in a config")
        self._depth += 1
        if self._depth > LIMITS["nesting"]:
            mark = self.peek_event().start_mark
            raise ConfigError(f"line {mark.line + 1}: nested deeper than {LIMITS['nesting']} levels")
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if isinstance(key, list | dict):
                raise ConfigError(f"line {key_node.start_mark.line + 1}: a mapping key must be a plain value")
            if key in seen:
                raise ConfigError(f"line {key_node.start_mark.line + 1}: duplicate key {quote(key)}")
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def read_yaml(path: Path, what: str = "config") -> Any:
    """Read a YAML file with :class:`_Loader`: at most ``LIMITS['file_bytes']``, UTF-8.

    Raises
    ------
    ConfigError
        One line naming the file and the problem.
    """
    try:
        with open(path, "rb") as f:
            raw = f.read(LIMITS["file_bytes"] + 1)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read {what} ({exc.strerror or exc})") from exc
    if len(raw) > LIMITS["file_bytes"]:
        raise ConfigError(f"{path}: larger than {LIMITS['file_bytes']:,} bytes; not a {what}")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{path}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start})"
        ) from exc
    if "\0" in text:
        raise ConfigError(f"{path}: holds a NUL character; not a {what}")
    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 (a SafeLoader subclass)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{path}: not valid YAML{where}") from exc
    except (ValueError, RecursionError) as exc:  # e.g. an integer of more than 4300 digits
        raise ConfigError(f"{path}: not a usable {what} ({quote(str(exc).splitlines()[0])})") from exc
