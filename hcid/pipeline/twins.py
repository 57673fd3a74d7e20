"""The twins of ``hcid analyse`` (SPEC 10): a group's fitted model (FF twin) and the same without
feedforward (FB twin), simulated, identified and calibrated in a run directory of their own, and
the W a calibration gives (:mod:`hcid.pipeline.analyse`)."""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from hcid import methods, tables
from hcid.config import Config, HCModel, Loop
from hcid.errors import ConfigError, DataError
from hcid.hcfit.determined import Simulated, group_model
from hcid.io import folders
from hcid.io.resolve import parse_config
from hcid.loop.hcmodel import check_closed_loops
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
    "TWIN_RANGES",
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
    "forget_twins",
    "group_models",
    "group_slug",
    "pool_twins",
    "separates",
    "twin_config_raw",
    "twin_dir_ready",
    "twin_model",
    "twin_rate",
    "twin_remnant",
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


#: What the twins' config takes of each value (:mod:`hcid.config.parse`, its ``models`` and
#: ``loop`` sections): the lowest, the highest, and whether the lowest itself is refused (the FF
#: twin's TI must be above 0: its Kpt is). ``kn`` is ``loop.remnant_gain``.
TWIN_RANGES = {
    "Kpt": (0.0, 10.0, False),
    "TI": (0.0, 10.0, True),
    "tau_pt": (-2.0, 2.0, False),
    "Kpe": (0.0, 100.0, True),
    "TL": (0.0, 10.0, False),
    "tau_pe": (0.0, 2.0, True),
    "w_nms": (0.0, 1e3, True),
    "zeta_nms": (0.0, 10.0, True),
    "kn": (0.0, 1e3, False),
    "w_n": (0.0, 1e3, True),
    "zeta_n": (0.0, 10.0, True),
}
# The HC model's path parameters (the twins' ``models`` section); delays in whole samples.
_PATH_PARAMETERS = ("Kpt", "TI", "tau_pt", "Kpe", "TL", "tau_pe")
_DELAYS = ("tau_pt", "tau_pe")
_REMNANT = ("kn", "w_n", "zeta_n")


def _into_range(name: str, value: float, sim_rate: float) -> tuple[float, str, str]:
    """One value as the twins simulate it: ``(value, change, problem)``, the change in words
    where it had to be brought into :data:`TWIN_RANGES`, the problem where it cannot be.

    A delay is whole samples at ``sim_rate`` (SPEC 1), and at least one where 0 is refused: a
    delay fitted at 0 s (on its search bound) or under half a sample says only that it is shorter
    than the fit can tell apart from the neuromuscular lag, and one sample, the shortest the
    simulation takes, changes the loop's phase by at most ``w / sim_rate`` rad (3 deg at 5 rad/s,
    100 Hz). A value above its range is brought to the range's top, one below a lowest that is
    taken to that lowest; one at or below a refused lowest of 0 (no gain, no damping) has no
    nearest value to stand for it, and is a problem.
    """
    lo, hi, open_lo = TWIN_RANGES[name]
    if not math.isfinite(value):
        return value, "", f"{name} is {value:g}"
    if name in _DELAYS:
        n = round(value * sim_rate)
        shortest = 1 if open_lo else math.ceil(lo * sim_rate - 1e-9)
        longest = math.floor(hi * sim_rate + 1e-9)
        if shortest <= n <= longest:
            return n / sim_rate, "", ""
        k = min(max(n, shortest), longest)
        to, was = k / sim_rate, f"{name} {value:.3f} s"
        if k == 1:
            return to, f"{was} raised to one sample of the twins' simulation, {to:g} s at {sim_rate:g} Hz", ""
        if n < shortest:
            return to, f"{was} raised to {to:g} s, the shortest the twins take", ""
        return to, f"{was} lowered to {to:g} s, the longest the twins take", ""
    if value > hi:
        return hi, f"{name} {value:.3g} lowered to {hi:g}, the most the twins take", ""
    if value <= lo and open_lo:
        return value, "", f"{name} is {value:.3g}, where the twins need a value above {lo:g}"
    if value < lo:
        return lo, f"{name} {value:.3g} raised to {lo:g}, the least the twins take", ""
    return value, "", ""


def _in_range(values: dict, names: Sequence[str], sim_rate: float) -> Simulated:
    brought = [_into_range(n, float(values[n]), sim_rate) for n in names]
    return Simulated(
        {n: v for n, (v, _, _) in zip(names, brought, strict=True)},
        tuple(c for _, c, _ in brought if c),
        "; ".join(p for _, _, p in brought if p),
    )


def twin_values(fitted: dict, sim_rate: float) -> dict[str, float]:
    """The FF twin's HC parameters (its paths' and its neuromuscular pair) as simulated at
    ``sim_rate`` (Hz): Kpt at least :data:`MIN_TWIN_KPT`, every value in :data:`TWIN_RANGES`
    (delays in whole samples, the error delay at least one; an anticipating tau_pt, < 0, reads the
    twins' periodic target ahead). :func:`twin_model` says what it changed."""
    return twin_model(fitted, sim_rate).values


def twin_model(fitted: dict, sim_rate: float, loop: Loop | None = None) -> Simulated:
    """A group's model as its twins simulate it at ``sim_rate`` (Hz), what had to be brought into
    the twins' ranges to make it (:data:`TWIN_RANGES`: a delay fitted at 0 s to one sample), and
    why the twins cannot be made from it at all: a value without a nearest one the twins take,
    or, given the study's ``loop`` (its plant), a loop with the plant or a feedforward path that
    is unstable as simulated (:func:`hcid.loop.hcmodel.check_closed_loops`, the twins' config's
    own check). What :func:`hcid.hcfit.determined.group_model` judges the group's candidate
    models by."""
    given = {**fitted, "Kpt": max(float(fitted["Kpt"]), MIN_TWIN_KPT)}
    sim = _in_range(given, (*_PATH_PARAMETERS, "w_nms", "zeta_nms"), sim_rate)
    if sim.problem or loop is None:
        return sim
    ff = HCModel("FF", **{k: sim.values[k] for k in _PATH_PARAMETERS})
    twin_loop = replace(loop, w_nms=sim.values["w_nms"], zeta_nms=sim.values["zeta_nms"])
    unstable = {  # the FB twin's loop is the FF twin's: checked alone first, to say which fails
        "FB": f"the loop with the plant is unstable as the twins simulate it at {sim_rate:g} Hz",
        "FF": "the feedforward path Ynms Kpt / Yc / (TI s + 1)^2 is unstable or improper with this plant",
    }
    for model in (replace(ff, name="FB", Kpt=0.0), ff):
        try:
            check_closed_loops((model,), twin_loop, 1.0 / sim_rate)
        except ConfigError:
            return Simulated(sim.values, sim.changes, unstable[model.name])
    return sim


def twin_remnant(remnant: tuple[float, float, float]) -> Simulated:
    """The group's remnant filter ``(kn, w_n, zeta_n)`` as its twins take it (:data:`TWIN_RANGES`),
    with what had to be brought into range, in words (values ``kn``, ``w_n``, ``zeta_n``)."""
    return _in_range(dict(zip(_REMNANT, remnant, strict=True)), _REMNANT, 1.0)  # no delay: any rate


def twin_config_raw(config: Config, fitted: dict, remnant: tuple, forcing: Path, twins: int, name: str):
    """The twins' config (as YAML would give it): the group's fitted model and its FB twin, every
    value in :data:`TWIN_RANGES` (:func:`twin_values`)."""
    loop_raw = dict(config.raw.get("loop", {}))
    kn, w_n, zeta_n = remnant
    rate, window = config.timing.output_rate, config.timing.window
    simulated = twin_values(fitted, twin_rate(rate))
    ff = {k: simulated[k] for k in _PATH_PARAMETERS}
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
    their selection paths and nb_ft, and their folder (under the run directory: their
    simulations, for the line statistics)."""

    first: int
    count: int
    paths: dict  # method -> (paths, nb_ft)
    folder: str


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
    return FbDraws(first, count, paths, f"twins/{slug}")


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


def twin_dir_ready(twin_dir: Path, text: str) -> None:
    """Keep the twins' earlier results only if their forcing functions are these (other data: new twins)."""
    path = twin_dir / "forcing.csv"
    if path.is_file() and path.read_text() != text:
        folders.remove_owned(twin_dir)


def group_models(config: Config, groups: dict, fitted: dict) -> tuple[dict, dict]:
    """Per group: its model from what its runs determine, of those its twins can be made from
    (:func:`group_model` judged by :func:`twin_model`: a value brought into the twins' range, or
    the nearest run's own model), and its twins' remnant filter: the medians over the runs whose
    remnant fit is off its search bounds, else over every run's fit (on a bound the filter's
    shape means little, its level still measures the remnant); where its runs make no such model,
    the model of every run of the study; each fallback in ``source``.

    ``groups`` maps a group to its runs (ids), ``fitted`` a run to ``({feedforward: HCFit},
    remnant fit or None)``; returns the groups' models (:class:`GroupModel`) and remnants
    ``(kn, w_n, zeta_n)``."""
    num_c, den_c = np.array(config.loop.plant.num), np.array(config.loop.plant.den)
    sim_rate = twin_rate(config.timing.output_rate)
    remnant_names = ("kn", "w_n", "zeta_n")

    def simulated(values: dict):
        return twin_model(values, sim_rate, config.loop)

    def model_of(seeds: list[int]):
        fits = [fitted[s][0][True] for s in seeds]
        return group_model(fits, [f"run {s}" for s in seeds], num_c, den_c, simulated)

    def remnant_of(seeds: list[int]):
        remnant_fits = [fitted[s][1] for s in seeds if fitted[s][1] is not None]
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
        return (*on_bounds, *remnant.changes), tuple(remnant.values[a] for a in remnant_names)

    every = sorted({s for seeds in groups.values() for s in seeds})

    def own_or_study(key, seeds, make, what: str):
        """The group's own, else the study's (all its runs), said so; only a study whose runs
        together cannot make it stops."""
        try:
            return make(seeds), ()
        except DataError as exc:
            if sorted(seeds) == every:
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
    for key, seeds in groups.items():
        model, model_note = own_or_study(key, seeds, model_of, "model")
        (remnant_notes, remnant), remnant_note = own_or_study(key, seeds, remnant_of, "remnant filter")
        models[key] = model.noting(*model_note, *remnant_notes, *remnant_note)
        remnants[key] = remnant
    return models, remnants


def forget_twins(run_dir: Path) -> None:
    """``--force``: every twins folder hcid made removed, so that they are made again."""
    for folder in sorted((run_dir / "twins").glob("*/")) if (run_dir / "twins").is_dir() else []:
        if (folder / folders.MANIFEST).is_file():
            folders.remove_owned(folder)
