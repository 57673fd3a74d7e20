"""Every table hcid writes: its file name, columns with their Arrow types, and its key.

The one home of each table's schema. Writers build their tables against these
schemas, :func:`hcid.io.results.read` checks what it reads against them, and the
report reads the columns named here. A leaf module: it imports only pyarrow, so
any layer may refer to a schema.

The run directory's layout (every file, what a row is, which command writes it) is
docs/tables.md's, with every column of every table.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import pyarrow as pa

__all__ = [
    "ANALYSIS",
    "ANALYSIS_GROUPS",
    "BREAKPOINTS",
    "EVIDENCE_TWINS",
    "FC_ESTIMATES",
    "FEEDBACK_RUNS",
    "CALIBRATION",
    "FRONTIER",
    "HANDOFF",
    "HC_LOOP",
    "HC_PARAMETERS",
    "IDENTIFY_LOG",
    "MEASURED",
    "ORDER_COLUMNS",
    "PARAMETER_UNITS",
    "RATES",
    "REMNANT_SPECTRUM",
    "RESIDUALS",
    "RUNS",
    "RUN_LOG",
    "SELECTED_COLUMNS",
    "SELECTION",
    "SESSION_FINDINGS",
    "SESSION_LINES",
    "SESSION_TRIALS",
    "SET_ASIDE",
    "SIMULATIONS",
    "SKIPPED",
    "SIMULATION_SUMMARY",
    "STUDY_EFFECTS",
    "Schema",
    "UNCERTAINTY_COLUMNS",
    "rate_column",
    "stage_choice",
    "thresholds",
]

_STR, _INT, _F64, _BOOL = pa.string(), pa.int64(), pa.float64(), pa.bool_()
#: Lists name their values "element", as Parquet does (so every reader of a table sees it);
#: :meth:`Schema.conform` gives a table built in memory this name before it is written.
_LIST = pa.list_(pa.field("element", pa.float64()))


@dataclass(frozen=True)
class Schema:
    """A table: file name in the run directory, typed columns in order, key columns.

    ``optional`` columns may be absent from a table written by an older hcid
    (a criterion added later); every other column must be there with its type.
    """

    file: str
    fields: tuple[tuple[str, pa.DataType], ...]
    key: tuple[str, ...]
    optional: tuple[str, ...] = ()
    #: Column -> unit, kept in the Parquet schema as each field's ``unit`` metadata.
    units: tuple[tuple[str, str], ...] = ()
    #: The command that writes the table, for the next step a refusal names ("" where several do).
    command: str = ""
    #: Columns written without dictionary encoding (every value its own: a record's noisy
    #: signals, a fit's V); list columns never are. The values read back are the same.
    plain: tuple[str, ...] = ()

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.fields)

    @property
    def arrow(self) -> pa.Schema:
        units = dict(self.units)
        return pa.schema(
            [pa.field(n, t, metadata={"unit": units[n]} if n in units else None) for n, t in self.fields]
        )

    def conform(self, table: pa.Table) -> pa.Table:
        """``table`` with each of this schema's columns in the schema's exact type.

        Types compare equal whatever a list names its values ("item" as built
        in memory, "element" as read from Parquet), but a Parquet file keeps the
        name: conformed, the same content always writes the same bytes.
        """
        wanted = dict(self.fields)
        for i, name in enumerate(table.column_names):
            kind = wanted.get(name)
            if kind is not None and str(table.schema.field(i).type) != str(kind):
                table = table.set_column(i, pa.field(name, kind), table.column(i).cast(kind))
        return table

    def problem(self, table: pa.Table, columns: Sequence[str] | None = None) -> str | None:
        """What is wrong with ``table`` against this schema (only ``columns`` if given), or None."""
        wanted = dict(self.fields)
        names = self.names if columns is None else tuple(columns)
        missing = [c for c in names if c not in table.column_names and c not in self.optional]
        if missing:
            return f"missing columns {missing}"
        for name in names:
            if name in table.column_names and name in wanted:
                found = table.schema.field(name).type
                if found != wanted[name]:
                    return f"column {name!r} is {found}, expected {wanted[name]}"
        return None


def _schema(file: str, fields: Iterable[tuple[str, pa.DataType]], key: tuple[str, ...], **kw) -> Schema:
    return Schema(file=file, fields=tuple(fields), key=key, **kw)


#: Channels of a simulated record, in table order (rad).
CHANNELS = ("ft", "fd", "e", "u", "theta", "n")
#: Signals of a measured record (rad).
SIGNALS = ("ft", "fd", "e", "u")
#: The structure integers of a selected model, in the order of the last tie rule (SPEC 4).
ORDER_COLUMNS = ("na", "nb_ft", "nb_e", "nk_ft", "nk_e")
#: What selection keeps of a frontier row.
SELECTED_COLUMNS = (*ORDER_COLUMNS, "d", "v", "vaf_estimation", "vaf_validation")
#: Engine column names (:meth:`hcid.arx.GridFit.to_arrow`) -> table names: input 1 is ft, input 2 e.
FRONTIER_NAMES = {"nb1": "nb_ft", "nb2": "nb_e", "nk1": "nk_ft", "nk2": "nk_e", "b1": "b_ft", "b2": "b_e"}

_REALIZATION_KEY = ("model", "seed")
_METHOD_KEY = ("model", "seed", "method")
_SELECTED_FIELDS = [(c, _INT) for c in (*ORDER_COLUMNS, "d")] + [
    (c, _F64) for c in ("v", "vaf_estimation", "vaf_validation")
]

SIMULATIONS = _schema(
    "simulations.parquet",
    [("model", _STR), ("seed", _INT), ("k", _INT), ("t", _F64)] + [(c, _F64) for c in CHANNELS],
    _REALIZATION_KEY,
    plain=("e", "u", "theta", "n"),  # ft, fd and t repeat in every realization
)
SIMULATION_SUMMARY = _schema(
    "simulation_summary.parquet",
    [("model", _STR), ("seed", _INT)]
    + [(c, _F64) for c in ("rms_e_deg", "noise_ratio", "noise_ratio_disturbance_only", "kn")],
    _REALIZATION_KEY,
)
MEASURED = _schema(
    "measured.parquet",
    [("model", _STR), ("seed", _INT), ("k", _INT), ("t", _F64)] + [(c, _F64) for c in SIGNALS],
    _REALIZATION_KEY,
    plain=("e", "u"),
)
#: ``runs.parquet`` (``hcid identify --data``): one row per imported run: ``model`` (the data
#: name), ``seed`` (the run id every table uses), ``file`` (as given), ``file_run`` (the file's
#: own run id), then one string column per factor of the data set (subject, condition, ...;
#: from a manifest or ``data.pattern``), which join every table by (model, seed).
RUNS = _schema(
    "runs.parquet",
    [("model", _STR), ("seed", _INT), ("file", _STR), ("file_run", _INT)],
    ("model", "seed"),
)
FRONTIER = _schema(
    "frontier.parquet",
    [("model", _STR), ("seed", _INT), ("method", _STR)]
    + _SELECTED_FIELDS
    + [("n_unstable", _INT), ("a", _LIST), ("b_ft", _LIST), ("b_e", _LIST)],
    _METHOD_KEY,
    plain=("v", "vaf_estimation", "vaf_validation"),
)
IDENTIFY_LOG = _schema(
    "identify_log.parquet",
    [("model", _STR), ("seed", _INT), ("method", _STR)]
    + [(c, _INT) for c in ("n_candidates", "n_unstable", "stage1_candidates", "stage1_unstable")]
    + [("seconds_stage1", _F64), ("seconds", _F64), ("worker", _STR)],
    _METHOD_KEY,
    optional=("worker",),
)
SELECTION = _schema(
    "selection.parquet",
    [("model", _STR), ("seed", _INT), ("method", _STR), ("w", _F64)] + _SELECTED_FIELDS,
    (*_METHOD_KEY, "w"),
)
BREAKPOINTS = _schema(
    "breakpoints.parquet",
    [("model", _STR), ("seed", _INT), ("method", _STR), ("w_from", _F64), ("w_to", _F64)] + _SELECTED_FIELDS,
    (*_METHOD_KEY, "w_from"),
)
CALIBRATION = _schema(
    "calibration.parquet",
    [("method", _STR), ("w", _F64)]
    + [(c, _F64) for c in ("fp_rate", "fp_low", "fp_high", "fn_rate", "fn_low", "fn_high")]
    + [("n_fb", _INT), ("n_ff", _INT)]
    + [(c, _F64) for c in ("target_rate", "safe_low", "safe_high", "recommended")],
    ("method", "w"),
)
RATES = _schema(
    "rates.parquet",
    [("method", _STR), ("model", _STR), ("error", _STR), ("w", _F64), ("k", _INT), ("n", _INT)]
    + [(c, _F64) for c in ("rate", "low", "high")],
    ("method", "model", "w"),
)
HANDOFF = _schema(
    "handoff.parquet",
    [("model", _STR), ("seed", _INT), ("method", _STR), ("stage", _STR), ("signal", _STR)]
    + [("vaf_noise_free", _F64), ("vaf_noise_free_record", _F64)],
    (*_METHOD_KEY, "stage"),
)
RUN_LOG = _schema(
    "run_log.parquet",
    [("stage", _STR), ("seconds", _F64), ("jobs", _INT), ("finished", _STR)],
    ("stage", "finished"),
)


def stage_choice(stage: str, inputs: Sequence[str]) -> Schema:
    """``<stage>.parquet``: the model a non-final stage hands on, per model and seed.

    Its inputs name the order columns (``nb_ft``, ``nb_fd`` for stage 1, whose inputs are ft and fd).
    """
    i1, i2 = inputs[0], inputs[1]
    return _schema(
        f"{stage}.parquet",
        [("model", _STR), ("seed", _INT)]
        + [(c, _INT) for c in ("na", f"nb_{i1}", f"nb_{i2}", f"nk_{i1}", f"nk_{i2}")]
        + [("v", _F64), ("n_candidates", _INT), ("n_unstable", _INT)],
        _REALIZATION_KEY,
    )


#: Sampling uncertainty of the thresholds (SPEC 9), added after the first release: optional on reading.
#: ``p_w_fp_at_paper``: P(W_FP >= the paper's W_FP) for a study of the paper's 50 realizations;
#: ``w_fn_low``, ``w_fn_high``: bootstrap 95% interval of W_FN; ``p_w_fn_at_paper``: the bootstrap
#: share of W_FN at or above the paper's.
UNCERTAINTY_COLUMNS = ("p_w_fp_at_paper", "w_fn_low", "w_fn_high", "p_w_fn_at_paper")


def rate_column(criterion_column: str) -> str:
    """The column of the error rate at a criterion's W (``w_bic`` -> ``rate_at_w_bic``)."""
    return f"rate_at_{criterion_column}"


def thresholds(criterion_columns: Sequence[str] = ()) -> Schema:
    """``thresholds.parquet``: per method and model, Nf, each criterion's W, W_FP (FB) and W_FN (FF),
    their sampling uncertainty, and the error rate (FB: false positive, FF: false negative) at
    each criterion's W.

    ``criterion_columns`` are the ``w_<name>`` columns of the configured criteria
    (:attr:`hcid.selection.criteria.Criterion.column`); a reader passes none and finds them
    by name.
    """
    rates = [rate_column(c) for c in criterion_columns]
    return _schema(
        "thresholds.parquet",
        [
            ("method", _STR),
            ("model", _STR),
            ("has_feedforward", _BOOL),
            ("n_realizations", _INT),
            ("nf", _INT),
        ]
        + [(c, _F64) for c in criterion_columns]
        + [("w_fp", _F64), ("w_fn", _F64)]
        + [(c, _F64) for c in UNCERTAINTY_COLUMNS]
        + [(c, _F64) for c in rates],
        ("method", "model"),
        optional=(*criterion_columns, *UNCERTAINTY_COLUMNS, *rates),
    )


# --------------------------------------------------------------------------- analyses of selected models

#: The selected model's columns in the analysis tables (orders, delays, V, the ARX model's VAF).
_SELECTED_MODEL_FIELDS = [(c, _INT) for c in ORDER_COLUMNS] + [("v", _F64), ("vaf_arx_validation", _F64)]
_ANALYSIS_KEY = ("model", "seed", "method", "w")

#: ``hc_parameters.parquet`` (``hcid fit-hc``): one row per record (model and seed, or
#: measured run), method, W and parameter of the parametric HC fit (SPEC 8).
#: ``w_source`` says where W came from (W_BIC, calibrated, --w); ``settings`` is a
#: digest of the fit settings the row was made with; ``status`` is ``fitted`` or why
#: not; ``true_value`` is the simulated model's (NaN for measured data or an
#: undefined parameter); ``at_bound`` flags an estimate on its bound; ``se`` is its
#: standard error and ``ci_low``, ``ci_high`` the 95% interval ``estimate +- 1.96 se``
#: (NaN on a bound), computed as ``covariance`` says (sandwich or gauss_newton);
#: ``parameter_status`` is ``determined`` or why not (:func:`hcid.hcfit.determined.parameter_status`);
#: ``target`` the estimator used (``auto`` resolved); ``cost``
#: and ``vaf_validation`` (%, the parametric model on the validation rows) repeat per row.
HC_PARAMETERS = _schema(
    "hc_parameters.parquet",
    [("model", _STR), ("seed", _INT), ("method", _STR), ("w", _F64), ("w_source", _STR)]
    + _SELECTED_MODEL_FIELDS
    + [("target", _STR), ("settings", _STR), ("status", _STR), ("parameter", _STR), ("unit", _STR)]
    + [("estimate", _F64), ("se", _F64), ("ci_low", _F64), ("ci_high", _F64), ("covariance", _STR)]
    + [("true_value", _F64), ("lower", _F64), ("upper", _F64), ("at_bound", _BOOL)]
    + [("parameter_status", _STR)]
    + [("cost", _F64), ("vaf_validation", _F64), ("starts", _INT)],
    (*_ANALYSIS_KEY, "parameter"),
    # run directories written by older hcid lack these: read without them
    optional=("se", "ci_low", "ci_high", "covariance", "parameter_status"),
)
#: ``hc_loop.parquet`` (``hcid fit-hc``): one row per record, method, W and ``source``
#: (``arx``: the selected ARX model; ``fitted``: the parametric fit): crossover
#: (rad/s) and phase margin (deg) of ``He Yc``, the shares of var(u) through the
#: target path, the error path and the remnant (``share_remnant``, the remnant
#: ratio), and SPEC 1's remnant filter fitted to the remnant's spectrum
#: (``remnant_kn`` for unit white noise at ``kn_rate`` Hz; ``remnant_at_bound``: its w_n or
#: zeta_n on a bound of the search, the three then mean little). ``true_*`` are the
#: simulated model's loop (NaN for measured data).
HC_LOOP = _schema(
    "hc_loop.parquet",
    [("model", _STR), ("seed", _INT), ("method", _STR), ("w", _F64), ("w_source", _STR)]
    + _SELECTED_MODEL_FIELDS
    + [("source", _STR), ("crossover", _F64), ("phase_margin", _F64), ("n_crossovers", _INT)]
    + [("true_crossover", _F64), ("true_phase_margin", _F64)]
    + [("share_ft", _F64), ("share_e", _F64), ("share_remnant", _F64)]
    + [("remnant_kn", _F64), ("remnant_w_n", _F64), ("remnant_zeta_n", _F64), ("kn_rate", _F64)]
    + [("remnant_at_bound", _BOOL)],
    (*_ANALYSIS_KEY, "source"),
)
#: ``remnant_spectrum.parquet`` (``hcid fit-hc``): the remnant's Welch density (one-sided,
#: rad^2/Hz) and the fitted filter's, per record, method, W, source and frequency (rad/s).
REMNANT_SPECTRUM = _schema(
    "remnant_spectrum.parquet",
    [("model", _STR), ("seed", _INT), ("method", _STR), ("w", _F64), ("source", _STR)]
    + [("omega", _F64), ("psd", _F64), ("psd_fit", _F64)],
    (*_ANALYSIS_KEY, "source", "omega"),
)
#: ``residuals.parquet`` (``hcid fit-hc``): one row per record, method, W, series and lag:
#: the selected model's simulation-residual autocorrelation (``signal`` eps) and its
#: cross-correlation with each input (ft_s, e), the white-residual band (``bound``),
#: whether the lag is outside it, and the share of that series' lags outside.
RESIDUALS = _schema(
    "residuals.parquet",
    [("model", _STR), ("seed", _INT), ("method", _STR), ("w", _F64), ("w_source", _STR)]
    + _SELECTED_MODEL_FIELDS
    + [("signal", _STR), ("kind", _STR), ("lag", _INT), ("lag_s", _F64), ("correlation", _F64)]
    + [("bound", _F64), ("outside", _BOOL), ("share_outside", _F64), ("n", _INT), ("confidence", _F64)],
    (*_ANALYSIS_KEY, "signal", "lag"),
)


# --------------------------------------------------------------------------- hcid analyse

#: The parametric model's parameters (SPEC 8), as the analysis tables name their columns.
HC_PARAMETER_NAMES = ("Kpe", "TL", "tau_pe", "w_nms", "zeta_nms", "Kpt", "TI", "tau_pt")
#: Each parameter's unit ("-": none); hcid.config.fit_settings.UNITS is this.
PARAMETER_UNITS = {
    "Kpe": "-",
    "TL": "s",
    "tau_pe": "s",
    "w_nms": "rad/s",
    "zeta_nms": "-",
    "Kpt": "-",
    "TI": "s",
    "tau_pt": "s",
}
_SHARES = (
    "fp_rate", "fp_low", "fp_high", "fn_rate", "fn_low", "fn_high", "p_w_star", "power_w_star", "p_fourier",
    "power_fourier", "p_lr", "power_lr", "p_value", "power", "binomial_p", "median_power", "group_power",
    "fc_p", "share_remnant", "remnant_share_data", "alpha",
)  # fmt: skip
#: The units of the analysis tables' numeric columns (Parquet field metadata ``unit``; "-": none,
#: "1": a share or probability, "%").
_ANALYSIS_UNITS = tuple(
    {
        **dict.fromkeys(("w", "safe_low", "safe_high", "w_star", "fourier_size", "likelihood_ratio"), "-"),
        **dict.fromkeys(_SHARES, "1"),
        **dict.fromkeys(("vaf_arx_validation", "vaf_validation"), "%"),
        **{
            f"{prefix}{p}{suffix}": u
            for p, u in PARAMETER_UNITS.items()
            for prefix, suffix in (("", ""), ("", "_se"), ("twin_", ""), ("fitted_", ""))
        },
        "crossover": "rad/s",
        "phase_margin": "deg",
        "he_error_db": "dB",
        "he_error_deg": "deg",
        "ht_error_db": "dB",
        "ht_error_deg": "deg",
        "twin_w_n": "rad/s",
        **dict.fromkeys(("fc_chi2", "twin_kn", "twin_zeta_n"), "-"),
    }.items()
)
_RATE_FIELDS = [(c, _F64) for c in ("fp_rate", "fp_low", "fp_high", "fn_rate", "fn_low", "fn_high")]
_CHOICE_FIELDS = (
    [
        ("group", _STR),
        ("method", _STR),
        ("w", _F64),
        ("w_rule", _STR),
        ("uncertain", _BOOL),
        ("ff_twin", _STR),
    ]
    + [("safe_low", _F64), ("safe_high", _F64)]
    + _RATE_FIELDS
)

#: A fitted model against the data's own frequency response (SPEC 11,
#: :mod:`hcid.hcfit.consistency`): the chi-square statistic, its degrees of freedom and
#: p-value, the verdict in words (``contradicted by the data`` below p = 0.01, ``consistent
#: with the data``, or why there is no test), where its standard errors came from (``remnant``
#: beside the lines, or ``across n runs``), and the median |error| of He at the disturbance
#: lines and of Ht at the target lines against the Fourier-coefficient estimates (dB, deg).
_CONSISTENCY_FIELDS = [
    ("fc_chi2", _F64),
    ("fc_dof", _INT),
    ("fc_p", _F64),
    ("fc_verdict", _STR),
    ("fc_spread", _STR),
    ("he_error_db", _F64),
    ("he_error_deg", _F64),
    ("ht_error_db", _F64),
    ("ht_error_deg", _F64),
]

#: ``analysis.parquet`` (``hcid analyse``; also written as ``analysis.csv``): one row per
#: measured run (``data_set`` the data name, ``run_id`` its number in the set, ``file`` and the file's own
#: ``file_run``) and method: its group's W
#: (``w_rule``: ``safe interval``, or ``least total error (...)`` with ``uncertain``
#: true), the twins' false-positive and false-negative rates there with their exact 95%
#: bands, the selected structure, ``feedforward`` (nb_ft > 0), the ARX and parametric
#: models' validation VAF, the run's evidence (SPEC 11: its ``forcing_set`` of the group, its
#: feedforward threshold ``w_star``, model-free ``fourier_size`` and the parametric fits'
#: ``likelihood_ratio`` (with and without feedforward, at the lines), each with its sequential
#: p-value against its set's FB twins and how it was made (``p_*_method``: ``monte carlo``, or
#: ``gpd tail`` where fewer than 5 of every twin drawn reach it, SPEC 13), the FB twins that p-value
#: used (``fb_twins_*``: FB twins are drawn until 5 show at least the run's value, at most
#: ``--max-fb-twins``) and the twins' power at
#: the group's level, ``decided_by`` the statistic whose
#: twins' power is higher, whose ``p_value`` and ``power`` decide ``evidence``
#: (``feedforward`` or ``none shown``); ``evidence_uncertain`` where that power is below 0.8),
#: the estimator (``estimator``: lines, time, closed_loop or frequency) and the model's form (``hc_form``:
#: ``full``, or ``nms fixed`` where the neuromuscular pair was held at its literature values),
#: each parameter with its standard error and status (``<p>``, ``<p>_se``, ``<p>_status``:
#: ``determined`` or the reason it is not, SPEC 11; NaN and ``not fitted`` where not fitted),
#: the fitted loop's crossover (rad/s), phase margin (deg) and remnant share, the run's own
#: model against its data (the consistency columns), then one string column per factor.
ANALYSIS = _schema(
    "analysis.parquet",
    [("data_set", _STR), ("run_id", _INT), ("file", _STR), ("file_run", _INT)]
    + _CHOICE_FIELDS
    + [(c, _INT) for c in ORDER_COLUMNS]
    + [("feedforward_at_w", _BOOL), ("vaf_arx_validation", _F64)]
    + [("estimator", _STR), ("vaf_validation", _F64)]
    + [("forcing_set", _INT), ("w_star", _F64), ("p_w_star", _F64), ("p_w_star_method", _STR)]
    + [("power_w_star", _F64), ("fb_twins_w_star", _INT)]
    + [("fourier_size", _F64), ("p_fourier", _F64), ("p_fourier_method", _STR), ("power_fourier", _F64)]
    + [("fb_twins_fourier", _INT), ("likelihood_ratio", _F64), ("p_lr", _F64), ("p_lr_method", _STR)]
    + [("power_lr", _F64), ("fb_twins_lr", _INT), ("decided_by", _STR)]
    + [
        ("p_value", _F64),
        ("p_method", _STR),
        ("power", _F64),
        ("evidence", _STR),
        ("evidence_uncertain", _BOOL),
    ]
    + [("hc_form", _STR)]
    + [f for p in HC_PARAMETER_NAMES for f in ((p, _F64), (f"{p}_se", _F64), (f"{p}_status", _STR))]
    + [("crossover", _F64), ("phase_margin", _F64), ("share_remnant", _F64), ("remnant_share_data", _F64)]
    + _CONSISTENCY_FIELDS,
    ("data_set", "run_id", "method"),
    units=_ANALYSIS_UNITS,
    command="hcid analyse",
)
#: ``analysis_groups.parquet`` (``hcid analyse``): one row per group of runs (``--by``) and
#: method: the W used and why, the safe interval, the twins' rates at W, the runs and how
#: many of them have feedforward there, and the twins (the group's fitted model as simulated,
#: ``twin_<p>``: delays in whole samples, Kpt at least 0.001; the FB twin has
#: Kpt = 0) with their remnant filter, number of realizations each (``twins``: the calibration's;
#: ``fb_twins``: the FB twins drawn for the runs' p-values, the most over the forcing sets) and
#: run directory; ``ff_twin``
#: says whose feedforward they carry (``own`` or the ``study``'s strongest) and ``fitted_<p>`` the
#: group's own model (the values its runs determine, below), as fitted. ``twin_source`` says how
#: the group's model was built (medians of the values its runs determine, or a stated fallback),
#: ``twin_undetermined`` names the parameters no run of the group determines (the literature
#: NMS, or their median over all runs brought into the plausible range, is used);
#: ``n_contradicted`` counts the runs whose own model the data contradict, and the consistency
#: columns test the group's model against its runs (SPEC 11).
ANALYSIS_GROUPS = _schema(
    "analysis_groups.parquet",
    _CHOICE_FIELDS
    + [("n_runs", _INT), ("n_feedforward_at_w", _INT)]
    + [("verdict", _STR), ("n_evidence", _INT), ("binomial_p", _F64), ("median_power", _F64)]
    + [("group_power", _F64), ("alpha", _F64), ("forcing_sets", _INT), ("decided_by", _STR)]
    + [(f"twin_{p}", _F64) for p in HC_PARAMETER_NAMES]
    + [(f"fitted_{p}", _F64) for p in HC_PARAMETER_NAMES]
    + [("twin_kn", _F64), ("twin_w_n", _F64), ("twin_zeta_n", _F64), ("twins", _INT), ("fb_twins", _INT)]
    + [("twins_folder", _STR)]
    + [("twin_source", _STR), ("twin_undetermined", _STR), ("n_contradicted", _INT)]
    + _CONSISTENCY_FIELDS,
    ("group", "method"),
    units=_ANALYSIS_UNITS,
    command="hcid analyse",
)
#: ``fc_estimates.parquet`` (``hcid analyse``): the model-free (Fourier-coefficient, SPEC 10)
#: estimates per group and forcing line: ``path`` ``e`` (He at a disturbance line) or ``ft``
#: (Ht at a target line, He interpolated there; ``extrapolated`` beyond the disturbance
#: lines), the group's coefficient average as magnitude (dB) and phase (deg), its spread
#: across runs (sd, dB and deg), and the group's fitted parametric model there (``model_db``,
#: ``model_deg``). At a target line, the model inversion ``Ht Yc`` (SPEC 11: 1 is the exact
#: inverse of the plant): ``inversion`` its magnitude (linear) and ``inversion_deg`` its phase
#: of the group's estimate, ``inversion_sd`` and ``inversion_sd_deg`` their spread across runs,
#: ``inversion_median``, ``inversion_q25`` and ``inversion_q75`` the median and quartiles of the
#: runs' own magnitudes (NaN at a disturbance line). A group whose design allows no estimate has
#: one row with ``problem`` set.
#: ``evidence_twins.parquet`` (``hcid analyse``): the twins each run's p-value is judged against
#: (SPEC 11): per group, method, forcing set, twin (``FB`` or ``FF``) and realization in the
#: order drawn, its feedforward threshold ``w_star`` (NaN for an FB twin drawn for the
#: line statistics only) and its ``fourier_size`` and ``likelihood_ratio`` (NaN where the forcing
#: has no lines).
EVIDENCE_TWINS = _schema(
    "evidence_twins.parquet",
    [("group", _STR), ("method", _STR), ("forcing_set", _INT), ("twin", _STR), ("seed", _INT)]
    + [("w_star", _F64), ("fourier_size", _F64), ("likelihood_ratio", _F64)],
    ("group", "method", "forcing_set", "twin", "seed"),
)
#: ``set_aside.parquet`` (``hcid analyse --skip-unreadable``): every file of the data set that could
#: not be read and was left out of the analysis, with the one-line reason (empty when none was).
SET_ASIDE = _schema("set_aside.parquet", [("file", _STR), ("reason", _STR)], ("file",))
FC_ESTIMATES = _schema(
    "fc_estimates.parquet",
    [("group", _STR), ("path", _STR), ("omega", _F64), ("magnitude_db", _F64), ("phase_deg", _F64)]
    + [("sd_db", _F64), ("sd_deg", _F64), ("extrapolated", _BOOL), ("n_runs", _INT)]
    + [("model_db", _F64), ("model_deg", _F64)]
    + [("inversion", _F64), ("inversion_deg", _F64), ("inversion_sd", _F64), ("inversion_sd_deg", _F64)]
    + [("inversion_median", _F64), ("inversion_q25", _F64), ("inversion_q75", _F64)]
    + [("problem", _STR)],
    ("group", "path", "omega"),
    optional=("inversion_median", "inversion_q25", "inversion_q75"),  # absent before 2026-11-27
)
#: ``skipped.parquet`` (``hcid analyse``): every file a folder or glob of ``--data`` found that is
#: not a run (not of a data format, left out by ``data.exclude``, a copy of a recording in another
#: format), with the one-line reason; empty when none was.
SKIPPED = _schema("skipped.parquet", [("file", _STR), ("reason", _STR)], ("file",))
#: ``session_trials.parquet`` (a whole experiment, SPEC 12): one row per run, its kind from the
#: data, its lines, and its u predicted by the person's model from the other kind of trials, then
#: its factors (docs/tables.md).
SESSION_TRIALS = _schema(
    "session_trials.parquet",
    [("data_set", _STR), ("run_id", _INT), ("file", _STR), ("person", _STR), ("kind", _STR)]
    + [("target_lines", _STR), ("disturbance_lines", _STR), ("problem", _STR), ("predicted_by", _STR)]
    + [("error_fb", _F64), ("error_ff", _F64), ("lines_error_fb", _F64), ("lines_error_ff", _F64)],
    ("run_id",),
)
#: ``session_lines.parquet`` (a whole experiment): per person (and ``median``), source of trials
#: and line: the responses, He, Ht and the model inversion |Ht Yc| (docs/tables.md).
SESSION_LINES = _schema(
    "session_lines.parquet",
    [("person", _STR), ("source", _STR), ("omega", _F64), ("hz", _F64)]
    + [("h_ur_db", _F64), ("h_ur_deg", _F64), ("h_ud_db", _F64), ("h_ud_deg", _F64)]
    + [("he_db", _F64), ("he_deg", _F64), ("ht_db", _F64), ("ht_deg", _F64)]
    + [("inversion", _F64), ("inversion_deg", _F64), ("inversion_q25", _F64), ("inversion_q75", _F64)]
    + [("he_measured", _BOOL), ("n_target_trials", _INT), ("n_disturbance_trials", _INT)],
    ("person", "source", "omega"),
)
#: ``session_findings.parquet`` (a whole experiment): the study's comparisons, one row each, with
#: what ``low`` and ``high`` are (``spread``) and the test behind ``p`` (docs/tables.md).
SESSION_FINDINGS = _schema(
    "session_findings.parquet",
    [("finding", _STR), ("person", _STR), ("source", _STR), ("quantity", _STR), ("band", _STR)]
    + [("omega", _F64), ("estimate", _F64), ("low", _F64), ("high", _F64), ("spread", _STR)]
    + [("p", _F64), ("test", _STR), ("n", _INT)],
    ("finding", "person", "source", "quantity", "band", "omega"),
)
#: ``feedback_runs.parquet`` (a whole experiment): each disturbance-only run's feedback alone per
#: method: the ARX model without the target path at W_BIC and the parametric feedback fit.
FEEDBACK_RUNS = _schema(
    "feedback_runs.parquet",
    [("data_set", _STR), ("run_id", _INT), ("person", _STR), ("method", _STR), ("w", _F64)]
    + [("na", _INT), ("nb_e", _INT), ("nk_e", _INT), ("vaf_validation", _F64)]
    + [("fit_target", _STR), ("fit_vaf_validation", _F64), ("crossover", _F64), ("phase_margin", _F64)]
    + [
        field_
        for p in HC_PARAMETER_NAMES
        if p not in ("Kpt", "TI", "tau_pt")  # the feedback path's alone
        for field_ in ((p, _F64), (f"{p}_se", _F64), (f"{p}_status", _STR))
    ],
    ("run_id", "method"),
)
#: ``study_effects.parquet`` (``hcid analyse --compare FACTOR``): per source (a method's fits, or
#: ``model-free``), quantity and level against the reference, each test's effect with its 95%
#: interval, p and Holm's p (docs/tables.md).
STUDY_EFFECTS = _schema(
    "study_effects.parquet",
    [("source", _STR), ("quantity", _STR), ("effect", _STR), ("estimate", _F64), ("low", _F64)]
    + [("high", _F64), ("p", _F64), ("p_holm", _F64), ("test", _STR), ("subjects", _INT), ("runs", _INT)]
    + [("left_out", _INT), ("unit", _STR), ("note", _STR)],
    ("source", "quantity", "effect", "test"),
)
