"""What the report shows, computed from a run's tables: curves over W, selected
models' frequency responses, and errors against the true paths.

Pure functions over Arrow tables, arrays and the run's config; no drawing, no I/O.
The verdicts on the paper's claims are in :mod:`hcid.report.verdicts`.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import pyarrow.compute  # noqa: F401  (pa.compute)

from hcid.arx.response import path_response
from hcid.config import Config, paper
from hcid.io.results import frontiers, split_by_key
from hcid.loop.hcmodel import true_response
from hcid.tables import ORDER_COLUMNS

__all__ = [
    "Curves",
    "DataStructure",
    "Responses",
    "compute_curves",
    "compute_data_structure",
    "compute_errors",
    "compute_responses",
    "data_summary_rows",
    "disturbance_band",
    "frequency_grid",
    "reference_feedforward",
]


def frequency_grid(n: int = 200) -> np.ndarray:
    """SPEC 5: log grid over :data:`hcid.config.paper.FREQUENCY_RANGE` (0.1..30 rad/s)."""
    return np.geomspace(*paper.FREQUENCY_RANGE, n)


def disturbance_band(config: Config) -> tuple[float, float]:
    """Lowest and highest disturbance frequency (rad/s), where estimates are expected to be
    accurate (SPEC 5: 0.23..17.33 rad/s for the paper's 20 sines); :attr:`Config.disturbance_band`."""
    return config.disturbance_band


# --------------------------------------------------------------------------- curves over W


@dataclass(frozen=True)
class Curves:
    """Per (model, method): mean and sd of the selected models' VAF, and mean nb_ft, over W."""

    w: np.ndarray
    vaf_mean: dict[tuple[str, str], np.ndarray]
    vaf_sd: dict[tuple[str, str], np.ndarray]
    nb_ft_mean: dict[tuple[str, str], np.ndarray]


def compute_curves(selection_table: pa.Table) -> Curves:
    """Average the selections of ``selection.parquet`` over realizations, per W."""
    w_all = selection_table.column("w").to_numpy()
    w = np.unique(w_all)
    vaf_mean, vaf_sd, nb_mean = {}, {}, {}
    for (model, method), t in split_by_key(selection_table, ("model", "method")).items():
        tw = t.column("w").to_numpy()
        idx = np.searchsorted(w, tw)
        n_real = np.bincount(idx, minlength=w.size)
        vaf = t.column("vaf_estimation").to_numpy()
        nb = t.column("nb_ft").to_numpy().astype(float)
        mean = np.bincount(idx, vaf, minlength=w.size) / n_real
        sq = np.bincount(idx, vaf**2, minlength=w.size) / n_real
        vaf_mean[(model, method)] = mean
        vaf_sd[(model, method)] = np.sqrt(np.maximum(sq - mean**2, 0.0) * n_real / np.maximum(n_real - 1, 1))
        nb_mean[(model, method)] = np.bincount(idx, nb, minlength=w.size) / n_real
    return Curves(w=w, vaf_mean=vaf_mean, vaf_sd=vaf_sd, nb_ft_mean=nb_mean)


# --------------------------------------------------------------------------- frequency responses


@dataclass(frozen=True)
class Responses:
    """Selected models at one W per method, per (model, method), on a frequency grid (rad/s).

    ``hft[key]`` and ``he[key]`` have shape (realizations, frequencies);
    ``nb_ft[key]`` is the selected nb_ft per realization; ``band`` is the
    disturbance band (rad/s).
    """

    omega: np.ndarray
    band: tuple[float, float]
    hft: dict[tuple[str, str], np.ndarray]
    he: dict[tuple[str, str], np.ndarray]
    nb_ft: dict[tuple[str, str], np.ndarray]


def compute_responses(
    frontier: pa.Table, config: Config, w_of: Mapping[str, float], omega: np.ndarray | None = None
) -> Responses:
    """Frequency responses of the models selected at ``w_of[method]`` for every realization.

    Methods missing from ``w_of`` are left out.
    """
    omega = frequency_grid() if omega is None else omega
    dt = 1.0 / config.timing.output_rate
    shift = config.identify.target_shift
    hft: dict = {}
    he: dict = {}
    nb: dict = {}
    for (model, _seed, method), one in frontiers(frontier).items():
        if method not in w_of:
            continue
        row = int(one.select(w_of[method])[0])
        c = one.row_coefficients(row)
        key = (model, method)
        hft.setdefault(key, []).append(
            path_response(c["a"], c["b_ft"], int(one.nk_ft[row]), omega, dt, advance=shift)
        )
        he.setdefault(key, []).append(path_response(c["a"], c["b_e"], int(one.nk_e[row]), omega, dt))
        nb.setdefault(key, []).append(int(one.nb_ft[row]))
    return Responses(
        omega=omega,
        band=disturbance_band(config),
        hft={k: np.array(v) for k, v in hft.items()},
        he={k: np.array(v) for k, v in he.items()},
        nb_ft={k: np.array(v) for k, v in nb.items()},
    )


def reference_feedforward(config: Config, omega: np.ndarray) -> np.ndarray | None:
    """The FF model's feedforward with ``Kpt`` replaced by :data:`hcid.config.paper.KPT_FALSE_POSITIVE`
    (paper Fig. 7a: Kpt = 0.2), or None without a feedforward model."""
    ff = next((m for m in config.models if m.has_feedforward), None)
    if ff is None:
        return None
    return true_response(dataclasses.replace(ff, Kpt=paper.KPT_FALSE_POSITIVE), config.loop, omega)[0]


def compute_errors(h_id: np.ndarray, h_true: np.ndarray) -> dict[str, np.ndarray]:
    """Paper eq. 11-12: magnitude error and wrapped phase error (deg, in [0, 180]),
    mean and max over realizations (rows of ``h_id``)."""
    mag = np.abs(np.abs(h_id) - np.abs(h_true)[None, :])
    # An absent path (nb = 0) has no phase: it counts in the magnitude error only.
    phase = np.abs(np.degrees(np.angle(h_id * np.conj(h_true)[None, :])))
    phase[np.abs(h_id) == 0] = np.nan
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: no realization has the path
        return {
            "mag_mean": mag.mean(axis=0),
            "mag_max": mag.max(axis=0),
            "phase_mean": np.nanmean(phase, axis=0),
            "phase_max": np.nanmax(phase, axis=0),
        }


# --------------------------------------------------------------------------- measured data


@dataclass(frozen=True)
class DataStructure:
    """Selected structure of every measured run over W: ``values[(run, method)][column]``."""

    w: np.ndarray
    values: dict[tuple[int, str], dict[str, np.ndarray]]


def compute_data_structure(selection_table: pa.Table, name: str) -> DataStructure | None:
    """The measured runs' selections from ``selection.parquet``, or None if it has none."""
    mask = pa.compute.equal(selection_table.column("model"), name)
    rows = selection_table.filter(mask)
    if rows.num_rows == 0:
        return None
    values = {}
    for (seed, method), t in split_by_key(rows, ("seed", "method")).items():
        values[(seed, method)] = {
            c: t.column(c).to_numpy() for c in ("w", *ORDER_COLUMNS, "d", "vaf_estimation")
        }
    w = next(iter(values.values()))["w"]
    return DataStructure(w=w, values=values)


def data_summary_rows(frontier: pa.Table, name: str, w_values: list[float]) -> list[list[str]]:
    """One row per run, method and W: the selected orders, delays (true ft delay in samples) and VAF."""
    mask = pa.compute.equal(frontier.column("model"), name)
    out = []
    for (_m, seed, method), one in frontiers(frontier.filter(mask)).items():
        orders = one.orders
        for w in w_values:
            row = int(one.select(w)[0])
            na, nbf, nbe, nkf, nke = (int(x) for x in orders[row])
            out.append(
                [
                    str(seed),
                    method,
                    f"{w:.3g}",
                    str(na),
                    str(nbf),
                    str(nbe),
                    f"{nkf}" if nbf else "-",
                    f"{nke}" if nbe else "-",
                    f"{one.vaf_estimation[row]:.1f}",
                    f"{one.vaf_validation[row]:.1f}",
                ]
            )
    return out
