"""The twins of ``hcid analyse`` (SPEC 10): a group's fitted model (FF twin) and the same without
feedforward (FB twin), simulated, identified and calibrated in a run directory of their own, and
the W a calibration gives (:mod:`hcid.pipeline.analyse`)."""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hcid import methods, tables
from hcid.config import Config
from hcid.errors import ConfigError, DataError
from hcid.hcfit.lines import feedforward_size, record_lines
from hcid.io import folders, results
from hcid.io.resolve import parse_config
from hcid.pipeline.execution import Execution
from hcid.pipeline.parallel import labelled
from hcid.pipeline.rundir import check_run_dir, using
from hcid.pipeline.studies import (
    calibrate_paths,
    calibrate_study,
    identify_study,
    model_paths,
    run_study,
    simulate_study,
)
from hcid.selection.calibration import calibrate

__all__ = [
    "MIN_TWIN_KPT",
    "TWIN_SIM_RATE",
    "FbDraws",
    "TwinSets",
    "TwinSource",
    "Twins",
    "calibrate_twins",
    "choose_w",
    "draw_fb_twins",
    "forcing_sets",
    "forcing_text",
    "group_slug",
    "pool_twins",
    "separates",
    "twin_config_raw",
    "twin_dir_ready",
    "twin_rate",
    "twin_sizes",
    "twin_values",
]

#: The twins' simulation rate: the smallest multiple of the analysis rate at or above this (Hz).
TWIN_SIM_RATE = 100.0


def group_slug(key: tuple[str, ...]) -> str:
    """The group's twins folder: its factor values made safe for a path, and a digest of the
    values themselves, so that two groups never share one folder ("a b" and "a-b")."""
    text = re.sub(r"[^A-Za-z0-9_.+-]", "-", "_".join(key) or "all")[:48]
    digest = hashlib.sha256(repr(tuple(key)).encode()).hexdigest()[:8]
    return f"{text}-{digest}"


def twin_rate(rate: float) -> float:
    return rate * max(1, math.ceil(TWIN_SIM_RATE / rate - 1e-9))


#: The FF twin's smallest Kpt: a group whose fitted Kpt is below it (nobody uses feedforward)
#: gets twins that nearly coincide, and the calibration says that no W separates them.
MIN_TWIN_KPT = 1e-3


def twin_values(fitted: dict, sim_rate: float) -> dict[str, float]:
    """The FF twin's HC parameters as simulated: delays in whole samples at ``sim_rate`` (an
    anticipating tau_pt, < 0, reads the twins' periodic target ahead), Kpt at least
    :data:`MIN_TWIN_KPT`."""
    ff = {k: float(fitted[k]) for k in ("Kpt", "TI", "tau_pt", "Kpe", "TL", "tau_pe")}
    ff["Kpt"] = max(ff["Kpt"], MIN_TWIN_KPT)
    for k in ("tau_pt", "tau_pe"):  # the simulation delays by whole samples (SPEC 1)
        ff[k] = round(ff[k] * sim_rate) / sim_rate
    return ff


def twin_config_raw(config: Config, fitted: dict, remnant: tuple, forcing: Path, twins: int, name: str):
    """The twins' config (as YAML would give it): the group's fitted model and its FB twin."""
    loop_raw = dict(config.raw.get("loop", {}))
    kn, w_n, zeta_n = remnant
    rate, window = config.timing.output_rate, config.timing.window
    sim = twin_rate(rate)
    ff = twin_values(fitted, sim)
    return {
        "name": name,
        "models": {"FB": {**ff, "Kpt": 0.0}, "FF": ff},
        "loop": {
            "plant": loop_raw["plant"]
            if "plant" in loop_raw
            else {"kind": "second_order", "K": loop_raw["Kc"], "wb": loop_raw["wb"]},
            "disturbance_at": config.loop.disturbance_at,
            "w_nms": float(fitted["w_nms"]),
            "zeta_nms": float(fitted["zeta_nms"]),
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
        "seeds": {"first": 1, "count": twins},
        "identify": config.raw["identify"],
        "selection": config.raw["selection"],
        "fit_hc": config.raw.get("fit_hc") or {},
    }


def forcing_sets(seeds: list[int], records: dict, config: Config) -> list[list[int]]:
    """The group's runs by their forcing functions (SPEC 11): runs whose ft and fd both agree
    within 0.1% RMS over the window share a set (each set gets twins of its own), in the order of
    their first run; so do runs whose ft and fd agree with the set's with both signs flipped.

    A flipped set needs no twins of its own: the twins' loop is linear and their remnant
    symmetric, so a twin driven by -ft, -fd with remnant n is exactly the negative of one driven
    by ft, fd with remnant -n, a remnant as likely as n; W* and the Fourier size do not see the
    sign (every signal of the identification and of the coefficients flips together). The set's
    twins, driven by its first run's functions, are therefore a sample of exactly the same
    distribution for its flipped runs."""
    n = round(config.timing.window * config.timing.output_rate)

    def agree(a: dict, b: dict, sign: float) -> bool:
        return all(
            np.sqrt(np.mean((a[k][:n] - sign * b[k][:n]) ** 2)) <= 1e-3 * np.sqrt(np.mean(a[k][:n] ** 2))
            for k in ("ft", "fd")
        )

    sets: list[list[int]] = []
    for seed in seeds:
        for members in sets:
            first = records[members[0]]
            if agree(first, records[seed], 1.0) or agree(first, records[seed], -1.0):
                members.append(seed)
                break
        else:
            sets.append([seed])
    return sets


@dataclass(frozen=True)
class TwinSets:
    """A group's twins for every forcing set of its runs, and their calibration pooled over the
    sets (one set: exactly that set's). ``runs[i]`` are the runs driven like ``sets[i]``."""

    kind: str
    sets: tuple
    runs: tuple
    calibrations: dict  # method -> Calibration over all sets' twins
    paths: dict  # method -> ((fb paths, fb nb_ft), (ff paths, ff nb_ft)) over all sets

    @property
    def model(self) -> dict:
        return self.sets[0].model

    @property
    def remnant(self) -> tuple:
        return self.sets[0].remnant

    @property
    def folder(self) -> str:
        return self.sets[0].folder

    def of_run(self, seed: int):
        """The twins driven by the run's own forcing functions."""
        return next(t for t, runs in zip(self.sets, self.runs, strict=True) if seed in runs)


def pool_twins(kind: str, sets: list, runs: list[list[int]], config: Config) -> TwinSets:
    """:class:`TwinSets` of the sets' twins; several sets are calibrated together (their FB twins'
    and FF twins' selection paths pooled, :func:`hcid.selection.calibration.calibrate`)."""
    if len(sets) == 1:
        only = sets[0]
        return TwinSets(kind, (only,), (tuple(runs[0]),), only.calibrations, only.paths)
    w = np.asarray(config.selection.w_grid, dtype=np.float64)
    calibrations, paths = {}, {}
    for method in methods.METHODS:
        fb = (
            [p for t in sets for p in t.paths[method][0][0]],
            [n for t in sets for n in t.paths[method][0][1]],
        )
        ff = (
            [p for t in sets for p in t.paths[method][1][0]],
            [n for t in sets for n in t.paths[method][1][1]],
        )
        paths[method] = (fb, ff)
        calibrations[method] = calibrate(method, fb, ff, w, config.selection.target_rate)
    return TwinSets(kind, tuple(sets), tuple(tuple(r) for r in runs), calibrations, paths)


def forcing_text(record: dict, n: int) -> str:
    """The group's forcing functions over one window, as the twins' file (CSV, full precision)."""
    lines = ["ft,fd"] + [
        f"{a:.17g},{b:.17g}" for a, b in zip(record["ft"][:n], record["fd"][:n], strict=True)
    ]
    return "\n".join(lines) + "\n"


def choose_w(cal) -> tuple[float, str, bool]:
    """The group's W and whether its decisions are uncertain.

    The recommended W of a safe interval; else the grid's least total error (FP + FN), the
    geometric middle of the range of grid points that tie for it (twins that nearly coincide
    tie almost everywhere: the smallest W would call everything feedforward). Uncertain when
    either twin's rate there exceeds the target rate.
    """
    if separates(cal):
        return float(cal.recommended), "safe interval", False
    total = cal.fp_rate + cal.fn_rate
    tied = np.flatnonzero(total <= total.min() + 1e-12)
    i = int(tied[len(tied) // 2])
    uncertain = max(cal.fp_rate[i], cal.fn_rate[i]) > cal.target_rate
    rule = (
        "least total error (no safe interval)"
        if uncertain
        else "least total error (no contiguous safe interval)"
    )
    return float(cal.w[i]), rule, uncertain


@dataclass(frozen=True)
class Twins:
    """One calibration of a group: its twins (``kind`` own or study), per method."""

    kind: str
    model: dict  # the FF twin's parameters as simulated (the FB twin: Kpt = 0)
    remnant: tuple  # kn, w_n, zeta_n
    folder: str  # under the run directory
    calibrations: dict  # method -> Calibration
    paths: dict  # method -> the twins' selection paths and nb_ft (studies.model_paths)
    fb_folder: str = ""  # where the FB twin was simulated when not in ``folder`` (shared)


def twin_sizes(twin: Twins, run_dir: Path, config: Config) -> dict[str, np.ndarray] | None:
    """Each FB and FF twin realization's model-free feedforward size
    (:func:`hcid.hcfit.lines.feedforward_size`), by twin; None where the forcing has no lines."""
    sizes = _sizes(run_dir / twin.folder, config.timing.output_rate)
    if twin.fb_folder and sizes:
        sizes["FB"] = _sizes(run_dir / twin.fb_folder, config.timing.output_rate).get("FB")
    return sizes if sizes and sizes.get("FB") is not None else None


def separates(cal) -> bool:
    """Whether a calibration has a safe interval (a W that tells its twins apart)."""
    return bool(cal.has_safe_interval and math.isfinite(cal.recommended))


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
    remnant: tuple[float, float, float]
    kn_rate: float
    forcing_set: int = 0

    @property
    def slug(self) -> str:
        return group_slug(self.key) + (f"-f{self.forcing_set}" if self.forcing_set else "")

    @property
    def whose(self) -> str:
        return f"{', '.join(self.key) or 'all runs'}{_set_label(self.forcing_set)}"


def calibrate_twins(
    source: TwinSource, twins: int, kind: str, execution: Execution, fb_from: Twins | None = None
) -> Twins:
    """Simulate, identify and calibrate one pair of ``twins`` realizations each of a group in
    ``RUN/twins/<group>[-f<set>][-study]`` (resumed when its inputs are the same, made anew when
    not). ``fb_from``: twins of the same group and forcing set whose FB twin is this one's (the
    study twins' is the own twins': the same loop, bit for bit), so only the FF twin is
    simulated and identified here."""
    config, model = source.config, source.model
    slug = source.slug + ("-study" if kind == "study" else "")

    def twins_raw(forcing: Path) -> dict:
        raw = twin_config_raw(config, model, source.remnant, forcing, twins, f"{config.name}_twins_{slug}")
        return raw if fb_from is None else {**raw, "models": {"FF": raw["models"]["FF"]}}

    with (
        _twin_folder(source, slug, kind, twins_raw) as (twin_dir, twin_config),
        labelled(f"{kind} twins of {source.whose}: "),
    ):
        if fb_from is None:
            run = calibrate_study(twin_config, twin_dir, execution=execution)
            found, paths, fb_folder = run.calibrations, run.paths, ""
        else:
            run_study(twin_config, twin_dir, execution=execution)
            ff = model_paths(twin_config, twin_dir, ("FF",))
            paths = {m: (fb_from.paths[m][0], ff[m][0]) for m in methods.METHODS}
            found = calibrate_paths(twin_config, twin_dir, paths)
            fb_folder = fb_from.fb_folder or fb_from.folder
        calibrations = {c.method: c for c in found}
    simulated = {**model, **twin_values(model, source.kn_rate)}
    return Twins(kind, simulated, source.remnant, f"twins/{slug}", calibrations, paths, fb_folder)


@dataclass(frozen=True)
class FbDraws:
    """More FB twins of one group and forcing set (seeds ``first`` on): per identified method
    their selection paths and nb_ft, and every twin's model-free feedforward size (None where
    the forcing has no lines)."""

    first: int
    count: int
    paths: dict  # method -> (paths, nb_ft)
    sizes: np.ndarray | None


def draw_fb_twins(
    source: TwinSource, first: int, count: int, method_names: Sequence[str], execution: Execution
) -> FbDraws:
    """FB twins ``first .. first + count - 1`` of a group (its fitted model without feedforward,
    driven by the forcing set's functions), simulated and identified by ``method_names`` only,
    in ``RUN/twins/<group>[-f<set>]-fb<first>`` (resumed; a method asked for later is added).
    The FB twin of ``--ff-twin study`` is the same loop, so one draw serves both."""
    config = source.config
    slug = f"{source.slug}-fb{first}"

    def fb_raw(forcing: Path) -> dict:
        raw = twin_config_raw(
            config, source.model, source.remnant, forcing, count, f"{config.name}_twins_{slug}"
        )
        return {**raw, "models": {"FB": raw["models"]["FB"]}, "seeds": {"first": first, "count": count}}

    with (
        _twin_folder(source, slug, "FB", fb_raw) as (twin_dir, twin_config),
        labelled(f"FB twins {first}-{first + count - 1} of {source.whose}: "),
    ):
        if method_names:
            identify_study(twin_config, twin_dir, method_names, execution=execution)
        elif not (twin_dir / tables.SIMULATIONS.file).exists():
            simulate_study(twin_config, twin_dir, execution=execution)
    found = model_paths(twin_config, twin_dir, ("FB",), method_names) if method_names else {}
    paths = {method: fb for method, (fb,) in found.items()}
    return FbDraws(first, count, paths, _sizes(twin_dir, config.timing.output_rate).get("FB"))


@contextmanager
def _twin_folder(source: TwinSource, slug: str, kind: str, make_raw):
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
                f"group {', '.join(key) or 'all runs'}: its twins ({kind}: the group's fitted model, "
                f"medians over its runs{', with the study feedforward' if kind == 'study' else ''}) "
                f"cannot be simulated: {exc}; look at its runs' fits, or group them otherwise (--by)"
            ) from None
        try:
            check_run_dir(twin_config, twin_dir, "simulate")
        except DataError:  # the group's fitted model changed (other settings): new twins
            folders.remove_owned(twin_dir, [n for n in folders.owned_files(twin_dir) if n != "forcing.csv"])
        yield twin_dir, twin_config


def _set_label(forcing_set: int) -> str:
    return f", forcing set {forcing_set}" if forcing_set else ""


def _sizes(folder: Path, rate: float) -> dict[str, np.ndarray]:
    """Each twin realization's model-free feedforward size in a twin folder, by model (in seed
    order); empty where the forcing has no lines."""
    records = results.records(results.read(tables.SIMULATIONS, folder), folder / tables.SIMULATIONS.file)
    out: dict[str, list[float]] = {}
    try:
        for (model, _), r in sorted(records.items()):
            out.setdefault(model, []).append(feedforward_size(record_lines(r, rate)))
    except DataError:
        return {}
    return {k: np.array(v) for k, v in out.items()}


def twin_dir_ready(twin_dir: Path, text: str) -> None:
    """Keep the twins' earlier results only if their forcing functions are these (other data: new twins)."""
    path = twin_dir / "forcing.csv"
    if path.is_file() and path.read_text() != text:
        folders.remove_owned(twin_dir)
