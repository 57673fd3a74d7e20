"""The twins of ``hcid analyse`` (SPEC 10): a group's fitted model (FF twin) and the same without
feedforward (FB twin), simulated, identified and calibrated in a run directory of their own, and
the W a calibration gives (:mod:`hcid.pipeline.analyse`)."""

from __future__ import annotations

import contextlib
import functools
import hashlib
import re
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

import numpy as np

from hcid import methods, tables
from hcid.assembly.resolve import parse_config
from hcid.config import Config
from hcid.errors import ConfigError, DataError
from hcid.hcfit.determined import GroupModel, group_model
from hcid.io import folders
from hcid.pipeline.execution import Execution
from hcid.pipeline.fit_hc import RunFits
from hcid.pipeline.parallel import labelled
from hcid.pipeline.rundir import check_run_dir, using
from hcid.pipeline.studies import calibrate_paths, identify_studies, model_paths, simulate_studies
from hcid.pipeline.sweep import sweep_study
from hcid.pipeline.twin_values import (
    PATH_PARAMETERS,
    Remnant,
    twin_model,
    twin_rate,
    twin_remnant,
    twin_values,
)
from hcid.selection.calibration import Calibration, Selections, TwinPaths, calibrate

__all__ = [
    "FfTwin",
    "FbDraws",
    "TwinSets",
    "TwinSource",
    "Twins",
    "calibrate_twin_sets",
    "calibrate_twins",
    "draw_fb_twin_sets",
    "draw_fb_twins",
    "forcing_sets",
    "forcing_text",
    "forget_twins",
    "group_models",
    "group_slug",
    "pool_twins",
    "twin_config_raw",
    "twin_dir_ready",
]


def group_slug(key: tuple[str, ...]) -> str:
    """The group's twins folder: its factor values made safe for a path, and a digest of the
    values themselves, so that two groups never share one folder ("a b" and "a-b")."""
    text = re.sub(r"[^A-Za-z0-9_.+-]", "-", "_".join(key) or "all")[:48]
    digest = hashlib.sha256(repr(tuple(key)).encode()).hexdigest()[:8]
    return f"{text}-{digest}"


def twin_config_raw(
    config: Config, fitted: dict, remnant: Remnant, forcing: Path, twins: int, name: str, stream: int = 0
) -> dict:
    """The twins' config (as YAML would give it): the group's fitted model and its FB twin, every
    value in :data:`hcid.pipeline.twin_values.TWIN_RANGES` (:func:`twin_values`); the remnant's
    noise ``stream`` (:attr:`TwinSource.noise_stream`; 0: none given)."""
    loop_raw = dict(config.raw.get("loop", {}))
    kn, w_n, zeta_n = remnant
    rate, window = config.timing.output_rate, config.timing.window
    simulated = twin_values(fitted, twin_rate(rate))
    ff = {k: simulated[k] for k in PATH_PARAMETERS}
    return {
        "name": name,
        "models": {"FB": {**ff, "Kpt": 0.0}, "FF": ff},
        "loop": {
            "plant": loop_raw["plant"]
            if "plant" in loop_raw
            else {"kind": "second_order", "K": loop_raw["Kc"], "wb": loop_raw["wb"]},
            "disturbance_at": config.loop.disturbance_at,
            "w_nms": simulated["w_nms"],
            "zeta_nms": simulated["zeta_nms"],
            "w_n": float(w_n),
            "zeta_n": float(zeta_n),
            "remnant_gain": float(kn),
        },
        "signals": {
            "target": {"kind": "file", "path": str(forcing), "column": "ft", "rate": rate, "start": 0.0},
            "disturbance": {"kind": "file", "path": str(forcing), "column": "fd", "rate": rate, "start": 0.0},
        },
        "timing": {
            "sim_rate": twin_rate(rate),
            "output_rate": rate,
            "run_in": 10.0,
            "window": window,
            "periods": 2,
        },
        "seeds": {"first": 1, "count": twins, **({"stream": stream} if stream else {})},
        "identify": config.raw["identify"],
        "selection": config.raw["selection"],
        "fit_hc": config.raw.get("fit_hc") or {},
    }


def forcing_sets(runs: list[int], records: dict, config: Config) -> list[list[int]]:
    """The group's runs by their forcing functions (SPEC 11): runs whose ft and fd both agree
    within 0.1% RMS over the window share a set (each set gets twins of its own), in the order of
    their first run; so do runs whose ft and fd agree with the set's with both signs flipped.

    A flipped set needs no twins of its own: the twins' loop is linear and their remnant
    symmetric, so a twin driven by -ft, -fd with remnant n is exactly the negative of one driven
    by ft, fd with remnant -n, a remnant as likely as n; W*, the Fourier size and the likelihood
    ratio do not see the sign (every signal of the identification and of the coefficients flips
    together, and the lines fits' residuals with them). The set's
    twins, driven by its first run's functions, are therefore a sample of exactly the same
    distribution for its flipped runs."""
    n = round(config.timing.window * config.timing.output_rate)

    def agree(a: dict, b: dict, sign: float) -> bool:
        return all(
            np.sqrt(np.mean((a[k][:n] - sign * b[k][:n]) ** 2)) <= 1e-3 * np.sqrt(np.mean(a[k][:n] ** 2))
            for k in ("ft", "fd")
        )

    sets: list[list[int]] = []
    for run in runs:
        for members in sets:
            first = records[members[0]]
            if agree(first, records[run], 1.0) or agree(first, records[run], -1.0):
                members.append(run)
                break
        else:
            sets.append([run])
    return sets


class FfTwin(StrEnum):
    """Whose feedforward a group's FF twin has (``--ff-twin``; ``analysis_groups.ff_twin``): the
    group's own fitted one, or the study's strongest."""

    OWN = "own"
    STUDY = "study"


@dataclass(frozen=True)
class TwinSets:
    """A group's twins for every forcing set of its runs, and their calibration pooled over the
    sets (one set: exactly that set's). ``runs[i]`` are the runs driven like ``sets[i]``."""

    kind: FfTwin
    sets: tuple[Twins, ...]
    runs: tuple[tuple[int, ...], ...]
    calibrations: dict[str, Calibration]  # per method, over all sets' twins
    paths: dict[str, TwinPaths]  # per method, over all sets

    @property
    def model(self) -> dict:
        return self.sets[0].model

    @property
    def remnant(self) -> Remnant:
        return self.sets[0].remnant

    @property
    def folder(self) -> str:
        return self.sets[0].folder

    def of_run(self, run: int) -> Twins:
        """The twins driven by the run's own forcing functions."""
        return next(t for t, members in zip(self.sets, self.runs, strict=True) if run in members)


def pool_twins(kind: FfTwin, sets: list[Twins], runs: list[list[int]], config: Config) -> TwinSets:
    """:class:`TwinSets` of the sets' twins; several sets are calibrated together (their FB twins'
    and FF twins' selection paths pooled, :func:`hcid.selection.calibration.calibrate`)."""
    if len(sets) == 1:
        only = sets[0]
        return TwinSets(kind, (only,), (tuple(runs[0]),), only.calibrations, only.paths)
    w = np.asarray(config.selection.w_grid, dtype=np.float64)
    calibrations, paths = {}, {}
    for method in methods.METHODS:
        fb, ff = (
            Selections(
                [p for t in sets for p in getattr(t.paths[method], twin).paths],
                [n for t in sets for n in getattr(t.paths[method], twin).nb_ft],
            )
            for twin in ("fb", "ff")
        )
        paths[method] = TwinPaths(fb, ff)
        calibrations[method] = calibrate(method, fb, ff, w, config.selection.target_rate)
    return TwinSets(kind, tuple(sets), tuple(tuple(r) for r in runs), calibrations, paths)


def forcing_text(record: dict, n: int) -> str:
    """The group's forcing functions over one window, as the twins' file (CSV, full precision)."""
    lines = ["ft,fd"] + [
        f"{a:.17g},{b:.17g}" for a, b in zip(record["ft"][:n], record["fd"][:n], strict=True)
    ]
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class Twins:
    """One calibration of a group: its twins (whose FF twin: ``kind``), per method."""

    kind: FfTwin
    model: dict  # the FF twin's parameters as simulated (the FB twin: Kpt = 0)
    remnant: Remnant
    folder: str  # under the run directory
    calibrations: dict[str, Calibration]  # per method
    paths: dict[str, TwinPaths]  # per method (studies.model_paths)
    fb_folder: str = ""  # where the FB twin was simulated when not in ``folder`` (shared)
    #: The records of ``folder`` and of ``fb_folder`` by (model, seed) where this command
    #: simulated them (held for the line statistics, not read back); None where an earlier did.
    records: dict | None = field(default=None, compare=False, repr=False)
    fb_records: dict | None = field(default=None, compare=False, repr=False)


@dataclass(frozen=True)
class TwinSource:
    """What one forcing set's twins of a group are made of: the study's ``config`` and
    ``run_dir``, the group (``key``, its factor values), the set's first run's ``record`` (its
    ft and fd drive the twins), the fitted HC values ``model`` (the FF twin; Kpt = 0 the FB
    twin), the remnant filter ``(kn, w_n, zeta_n)`` at ``kn_rate``, and the set's number
    (``forcing_set``, 0 for a group of one set)."""

    config: Config
    run_dir: Path
    key: tuple[str, ...]
    record: dict
    model: dict
    remnant: Remnant
    kn_rate: float
    forcing_set: int = 0

    @property
    def slug(self) -> str:
        return group_slug(self.key) + (f"-f{self.forcing_set}" if self.forcing_set else "")

    @property
    def noise_stream(self) -> int:
        """The twins' remnant noise stream (:attr:`hcid.config.Config.noise_stream`): a digest of
        the group's factor values and the set's first run's ft, fd and u, so that no two groups,
        forcing sets or studies draw their twins' remnants from the same noise (their runs would
        be judged against correlated twins), and the same data give the same twins. The record's
        samples, not a fitted value, are digested: they are the same bits on every machine. Every
        twin folder of one group and set (the calibration's, the study's FF twin, the more FB
        twins) shares it, so a seed's FB and FF twins share their noise."""
        digest = hashlib.sha256(repr(tuple(self.key)).encode())
        for name in ("ft", "fd", "u"):
            digest.update(np.ascontiguousarray(self.record[name], dtype=np.float64).tobytes())
        return int(digest.hexdigest()[:15], 16) or 1

    @property
    def whose(self) -> str:
        return f"{', '.join(self.key) or 'all runs'}{_set_label(self.forcing_set)}"


def calibrate_twins(
    source: TwinSource, twins: int, kind: FfTwin, execution: Execution, fb_from: Twins | None = None
) -> Twins:
    """Simulate, identify and calibrate one pair of ``twins`` realizations each of a group in
    ``RUN/twins/<group>[-f<set>][-study]`` (resumed when its inputs are the same, made anew when
    not). ``fb_from``: twins of the same group and forcing set whose FB twin is this one's (the
    study twins' is the own twins': the same loop, bit for bit), so only the FF twin is
    simulated and identified here."""
    return calibrate_twin_sets([(source, kind, fb_from)], twins, execution)[0]


def calibrate_twin_sets(
    requests: Sequence[tuple[TwinSource, FfTwin, Twins | None]], twins: int, execution: Execution
) -> list[Twins]:
    """:func:`calibrate_twins` of every ``(source, kind, fb_from)``, their simulations and
    identifications in one pool (:func:`hcid.pipeline.studies.identify_studies`): the workers
    stay busy across forcing sets and groups. Each folder's tables are those it gets alone."""
    with contextlib.ExitStack() as held:
        made, slugs = (
            [],
            [source.slug + ("-study" if kind is FfTwin.STUDY else "") for source, kind, _ in requests],
        )
        for (source, kind, fb_from), slug in zip(requests, slugs, strict=True):
            raw = functools.partial(_calibration_raw, source, twins, slug, fb_from is not None)
            made.append(held.enter_context(_twin_folder(source, slug, str(kind), raw)))
        with labelled(_batch_label(requests, lambda r: f"{r[1]} twins of {r[0].whose}")):
            identified = identify_studies(
                [(config, folder, None) for folder, config in made], execution=execution
            )
        out = []
        for (source, kind, fb_from), slug, (twin_dir, twin_config), run in zip(
            requests, slugs, made, identified, strict=True
        ):
            sweep_study(twin_config, twin_dir, run.frontiers)  # as run_study does
            if fb_from is None:
                both = model_paths(twin_config, twin_dir, ("FB", "FF"), frontiers=run.frontiers)
                paths = {m: TwinPaths(*both[m]) for m in methods.METHODS}
                fb_folder, fb_records = "", None
            else:
                ff = model_paths(twin_config, twin_dir, ("FF",), frontiers=run.frontiers)
                paths = {m: TwinPaths(fb_from.paths[m].fb, *ff[m]) for m in methods.METHODS}
                fb_folder = fb_from.fb_folder or fb_from.folder
                fb_records = fb_from.fb_records if fb_from.fb_folder else fb_from.records
            calibrations = {c.method: c for c in calibrate_paths(twin_config, twin_dir, paths)}
            simulated = {**source.model, **twin_values(source.model, source.kn_rate)}
            folder = f"twins/{slug}"
            made_now = run.simulation.records if run.simulation is not None else None
            out.append(
                Twins(
                    kind,
                    simulated,
                    source.remnant,
                    folder,
                    calibrations,
                    paths,
                    fb_folder,
                    made_now,
                    fb_records,
                )
            )
    return out


def _calibration_raw(source: TwinSource, twins: int, slug: str, ff_only: bool, forcing: Path) -> dict:
    """The calibration twins' config (:func:`twin_config_raw`), only the FF twin where the FB
    twin is another folder's."""
    config = source.config
    name, stream = f"{config.name}_twins_{slug}", source.noise_stream
    raw = twin_config_raw(config, source.model, source.remnant, forcing, twins, name, stream)
    return {**raw, "models": {"FF": raw["models"]["FF"]}} if ff_only else raw


def _batch_label(requests: Sequence, one) -> str:
    """A progress bar's prefix: the one request's own words, or how many forcing sets."""
    return f"{one(requests[0])}: " if len(requests) == 1 else f"twins of {len(requests)} forcing sets: "


@dataclass(frozen=True)
class FbDraws:
    """More FB twins of one group and forcing set (seeds ``first`` on): per identified method
    their selection paths and nb_ft, and their folder (under the run directory: their
    simulations, for the line statistics)."""

    first: int
    count: int
    paths: dict[str, Selections]  # per identified method
    folder: str
    #: Their records by (model, seed) where this command simulated them (None: an earlier command's).
    records: dict | None = field(default=None, compare=False, repr=False)


def draw_fb_twins(
    source: TwinSource, first: int, count: int, method_names: Sequence[str], execution: Execution
) -> FbDraws:
    """FB twins ``first .. first + count - 1`` of a group (its fitted model without feedforward,
    driven by the forcing set's functions), simulated and identified by ``method_names`` only,
    in ``RUN/twins/<group>[-f<set>]-fb<first>`` (resumed; a method asked for later is added).
    The FB twin of ``--ff-twin study`` is the same loop, so one draw serves both."""
    return draw_fb_twin_sets([(source, first, count, tuple(method_names))], execution)[0]


def draw_fb_twin_sets(
    requests: Sequence[tuple[TwinSource, int, int, Sequence[str]]], execution: Execution
) -> list[FbDraws]:
    """:func:`draw_fb_twins` of every ``(source, first, count, method_names)``, in one pool."""
    with contextlib.ExitStack() as held:
        made = []
        for source, first, count, _ in requests:
            slug = f"{source.slug}-fb{first}"
            raw = functools.partial(_draw_raw, source, first, count, slug)
            made.append(held.enter_context(_twin_folder(source, slug, "FB", raw)))
        identify = [i for i, r in enumerate(requests) if r[3]]
        simulate = [
            i for i, r in enumerate(requests)
            if not r[3] and not (made[i][0] / tables.SIMULATIONS.file).exists()
        ]  # fmt: skip
        label = _batch_label(requests, lambda r: f"FB twins {r[1]}-{r[1] + r[2] - 1} of {r[0].whose}")
        with labelled(label):
            runs = identify_studies(
                [(made[i][1], made[i][0], requests[i][3]) for i in identify], execution=execution
            )
            simulated = simulate_studies([(made[i][1], made[i][0]) for i in simulate], execution=execution)
        frontiers = dict(zip(identify, (r.frontiers for r in runs), strict=True))
        # The simulations made now, held for the line statistics (not read back).
        held = {i: r.simulation.records for i, r in zip(identify, runs, strict=True) if r.simulation}
        held.update({i: r.records for i, r in zip(simulate, simulated, strict=True)})
        out = []
        for i, (source, first, count, names) in enumerate(requests):
            twin_dir, twin_config = made[i]
            found = (
                model_paths(twin_config, twin_dir, ("FB",), names, frontiers=frontiers[i]) if names else {}
            )
            paths = {method: fb for method, (fb,) in found.items()}
            out.append(FbDraws(first, count, paths, f"twins/{source.slug}-fb{first}", held.get(i)))
    return out


def _draw_raw(source: TwinSource, first: int, count: int, slug: str, forcing: Path) -> dict:
    config = source.config
    name, stream = f"{config.name}_twins_{slug}", source.noise_stream
    raw = twin_config_raw(config, source.model, source.remnant, forcing, count, name, stream)
    return {**raw, "models": {"FB": raw["models"]["FB"]}, "seeds": {**raw["seeds"], "first": first}}


@contextmanager
def _twin_folder(source: TwinSource, slug: str, which: str, make_raw):
    """``RUN/twins/<slug>`` held and ready: the forcing set's functions in ``forcing.csv`` (earlier
    results of other forcing functions removed), the twins' config from ``make_raw(forcing path)``
    parsed, and earlier results of another config removed; yields ``(folder, config)``."""
    config, key = source.config, source.key
    twin_dir = source.run_dir / "twins" / slug
    with using(twin_dir):
        forcing = twin_dir / "forcing.csv"
        n = round(config.timing.window * config.timing.output_rate)
        text = forcing_text(source.record, n)
        twin_dir_ready(twin_dir, text)
        folders.atomic_write(forcing, lambda tmp: Path(tmp).write_text(text))
        raw = make_raw(forcing)
        given = {"target": source.record["ft"][:n], "disturbance": source.record["fd"][:n]}
        try:  # forcing.csv holds these values (full precision); built in memory, not read back
            twin_config = parse_config(raw, raw["name"], forcing=given)
        except ConfigError as exc:  # e.g. a median model that is unstable with the plant
            raise DataError(
                f"group {', '.join(key) or 'all runs'}: its twins ({which}: the group's fitted model, "
                f"medians over its runs{', with the study feedforward' if which == FfTwin.STUDY else ''}) "
                f"cannot be simulated: {exc}; look at its runs' fits, or group them otherwise (--by)"
            ) from None
        try:
            check_run_dir(twin_config, twin_dir, "simulate")
        except DataError:  # the group's fitted model changed (other settings): new twins
            folders.remove_owned(twin_dir, [n for n in folders.owned_files(twin_dir) if n != "forcing.csv"])
        yield twin_dir, twin_config


def _set_label(forcing_set: int) -> str:
    return f", forcing set {forcing_set}" if forcing_set else ""


def twin_dir_ready(twin_dir: Path, text: str) -> None:
    """Keep the twins' earlier results only if their forcing functions are these (other data: new twins)."""
    path = twin_dir / "forcing.csv"
    if path.is_file() and path.read_text() != text:
        folders.remove_owned(twin_dir)


def group_models(
    config: Config, groups: dict[tuple[str, ...], list[int]], fitted: dict[int, RunFits]
) -> tuple[dict[tuple[str, ...], GroupModel], dict[tuple[str, ...], Remnant]]:
    """Per group: its model from what its runs determine, of those its twins can be made from
    (:func:`group_model` judged by :func:`twin_model`: a value brought into the twins' range, or
    the nearest run's own model), and its twins' remnant filter: the medians over the runs whose
    remnant fit is off its search bounds, else over every run's fit (on a bound the filter's
    shape means little, its level still measures the remnant); where its runs make no such model,
    the model of every run of the study; each fallback in ``source``.

    ``groups`` maps a group to its runs (ids), ``fitted`` a run to its fits."""
    num_c, den_c = np.array(config.loop.plant.num), np.array(config.loop.plant.den)
    sim_rate = twin_rate(config.timing.output_rate)
    remnant_names = ("kn", "w_n", "zeta_n")

    def simulated(values: dict):
        return twin_model(values, sim_rate, config.loop)

    def model_of(runs: list[int]):
        fits = [fitted[r].with_ff for r in runs]
        return group_model(fits, [f"run {r}" for r in runs], num_c, den_c, simulated)

    def remnant_of(runs: list[int]):
        remnant_fits = [fitted[r].remnant for r in runs if fitted[r].remnant is not None]
        if not remnant_fits:
            raise DataError("no run's remnant could be fitted")
        off_bounds = [r for r in remnant_fits if not r.at_bound]
        medians = [
            float(np.median([getattr(r, a) for r in off_bounds or remnant_fits])) for a in remnant_names
        ]
        remnant = twin_remnant(tuple(medians))
        if remnant.problem:
            raise DataError(f"its remnant cannot make twins: {remnant.problem}")
        on_bounds = () if off_bounds else ("its remnant filter from fits on their search bounds",)
        return (*on_bounds, *remnant.changes), Remnant(*(remnant.values[a] for a in remnant_names))

    every = sorted({r for members in groups.values() for r in members})

    def own_or_study(key, members, make, what: str):
        """The group's own, else the study's (all its runs), said so; only a study whose runs
        together cannot make it stops."""
        try:
            return make(members), ()
        except DataError as exc:
            if sorted(members) == every:
                raise DataError(
                    f"group {group_slug(key)}: {exc}; look at its runs' fits or group them otherwise (--by)"
                ) from None
            try:
                return make(every), (f"its own runs cannot make twins ({exc}): the study's {what}",)
            except DataError as pooled:
                raise DataError(
                    f"group {group_slug(key)}: {exc}; nor can the study's runs together: {pooled}"
                ) from None

    models, remnants = {}, {}
    for key, members in groups.items():
        model, model_note = own_or_study(key, members, model_of, "model")
        (remnant_notes, remnant), remnant_note = own_or_study(key, members, remnant_of, "remnant filter")
        models[key] = model.noting(*model_note, *remnant_notes, *remnant_note)
        remnants[key] = remnant
    return models, remnants


def forget_twins(run_dir: Path) -> None:
    """``--force``: every twins folder hcid made removed, so that they are made again."""
    for folder in sorted((run_dir / "twins").glob("*/")) if (run_dir / "twins").is_dir() else []:
        if (folder / folders.MANIFEST).is_file():
            folders.remove_owned(folder)
