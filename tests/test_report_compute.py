"""Report computations against exact formulas (paper eq. 11-12)."""

import numpy as np
import pytest

from hcid.report.compute import compute_errors


def test_errors_wrap_phase_and_skip_absent_paths():
    # Paper eq. 11-12: a 350 deg phase difference is a 10 deg error; an absent path adds
    # its full magnitude error and no phase error.
    h_true = np.array([2.0 + 0j])
    h_id = np.array([[1.5 * np.exp(1j * np.radians(350.0))], [0.0 + 0j]])
    err = compute_errors(h_id, h_true)
    assert err["mag_mean"][0] == pytest.approx((0.5 + 2.0) / 2)
    assert err["mag_max"][0] == pytest.approx(2.0)
    assert err["phase_mean"][0] == pytest.approx(10.0)
    assert err["phase_max"][0] == pytest.approx(10.0)


def test_each_status_has_its_mark_in_the_run_table():
    # † undetermined, ‡ determined but to read with care, "(held)" held (the table's own note says
    # so; a degree sign had read as a unit: "10.1°" rad/s, issue 46).
    from hcid.report.run_table import with_se as _with_se

    def row(status, se=0.1):
        return {"Kpe": 33.5, "Kpe_se": se, "Kpe_status": status}

    assert _with_se(row("determined"), "Kpe") == "33.5 ± 0.1"
    assert _with_se(row("outside its plausible range"), "Kpe") == "33.5 ± 0.1‡"
    assert _with_se(row("not told from 0 (se above |value|)"), "Kpe") == "33.5 ± 0.1‡"
    assert _with_se(row("in a failed fit (validation VAF below 0%)", 3.8e-9), "Kpe") == "33.5†"  # no se
    assert _with_se(row("correlated with TL (r = -0.97)", 3.3e5), "Kpe") == "33.5†"
    assert _with_se(row("fixed at a literature value", float("nan")), "Kpe") == "33.5 (held)"


def test_the_evidence_figure_names_each_run_by_the_factors_that_differ():
    # Issue 46 (2): the figure's run numbers, keyed to subject and trial only in a caption, were
    # not read as whose they are. Each run is named by its number and the factors that differ
    # within the group (the group's own factor is the same for all), a number-like value with its
    # factor's name, at most three factors.
    from hcid.report.figures_hcfit import run_labels

    def _run_labels(runs):
        return run_labels(runs, [f for f in runs[0] if f not in ("run_id", "method")])

    runs = [
        {"run_id": i + 1, "method": "direct", "subject": s, "plant": "fo", "trial": t}
        for i, (s, t) in enumerate([("dp", "+1"), ("dp", "-1"), ("ef", "+1")])
    ]
    names = ["run 1: dp, trial +1", "run 2: dp, trial -1", "run 3: ef, trial +1"]
    assert [r["label"] for r in _run_labels(runs)] == names
    same = [{**r, "subject": "dp", "trial": "+1"} for r in runs]
    assert [r["label"] for r in _run_labels(same)] == ["run 1", "run 2", "run 3"]  # nothing differs
    many = [{"run_id": 1, "method": "direct", "a": i, "b": f"x{i}", "c": "y", "d": i, "e": i} for i in (0, 1)]
    assert _run_labels(many)[1]["label"] == "run 1: a 1, x1, d 1"


def test_the_data_check_table_gives_angles_in_whole_degrees():
    # Issue 46 (4): "1.1e+02 deg" where the console says 114 deg.
    from hcid.report.sections.study import _degrees

    assert (_degrees(114.2), _degrees(3.4), _degrees(float("nan"))) == ("114", "3", "-")


def test_no_per_subject_binomial_where_each_subject_has_one_run():
    # Issue 46 (10): a binomial over one run cannot reject (its p is alpha at best); with one run
    # per subject and group (the CPHS recordings --by trial) the per-subject summary is left out.
    from hcid.pipeline.summary import GroupSummary

    def summary(runs):
        group = {"group": "trial=+1", "method": "direct", "alpha": 0.05}
        return GroupSummary(group, runs, (0.9, 0.9), [], 2.0, 40.0)

    one_each = [{"subject": s, "p_value": 0.01} for s in ("dp", "ef", "gy")]
    assert summary(one_each).by_subject() == []
    two_each = one_each + [{"subject": s, "p_value": 0.5} for s in ("dp", "ef", "gy")]
    assert [row[:3] for row in summary(two_each).by_subject()] == [("dp", 1, 2), ("ef", 1, 2), ("gy", 1, 2)]


def test_no_model_feedforward_is_drawn_for_a_group_answered_without_it():
    # Issue 46 (7): a group-model Ht curve had been drawn for a condition answered NO FEEDFORWARD
    # SHOWN (its fitted Kpt above 0); now only where a method's verdict is FEEDFORWARD.
    from types import SimpleNamespace

    import pyarrow as pa

    from hcid import tables
    from hcid.assembly.resolve import load_config
    from hcid.report.sections.study import _fourier

    from .conftest import ROOT

    config = load_config(ROOT / "configs" / "lab_example.yaml")
    rows = [
        {"group": "g", "path": path, "omega": w, "magnitude_db": 0.0, "phase_deg": 0.0, "sd_db": 0.0,
         "sd_deg": 0.0, "extrapolated": False, "n_runs": 3, "model_db": 0.0, "model_deg": 0.0,
         "inversion": 1.0, "inversion_deg": 0.0, "inversion_sd": 0.0, "inversion_sd_deg": 0.0,
         "inversion_median": 1.0, "inversion_q25": 1.0, "inversion_q75": 1.0, "problem": ""}
        for path, w in (("e", 1.0), ("ft", 2.0))
    ]  # fmt: skip
    run = SimpleNamespace(
        config=config, fc_estimates=pa.Table.from_pylist(rows, schema=tables.FC_ESTIMATES.arrow)
    )
    fitted = {
        "Kpe": 2.0,
        "TL": 0.3,
        "tau_pe": 0.2,
        "w_nms": 10.1,
        "zeta_nms": 0.35,
        "Kpt": 0.5,
        "TI": 0.2,
        "tau_pt": 0.1,
    }
    group = {"group": "g", "twins_folder": "twins/g-1", **{f"fitted_{p}": v for p, v in fitted.items()}}
    for verdicts, drawn in (
        (("NO FEEDFORWARD SHOWN", "UNCERTAIN"), False),
        (("FEEDFORWARD", "UNCERTAIN"), True),
    ):
        groups = [
            {**group, "method": m, "verdict": v}
            for m, v in zip(("direct", "indirect"), verdicts, strict=True)
        ]
        (fc,), _ = _fourier(run, groups)
        assert (fc[3]["ft"] is not None) == drawn


def test_a_point_at_zero_inversion_is_drawn_whole():
    # Issue 46 (6): points at |Ht Yc| = 0 had been half clipped on the axis (ylim from 0).
    from hcid.report.figures_hcfit import plot_inversion

    rows = [
        {"path": "ft", "omega": w, "extrapolated": False, "inversion": m, "inversion_deg": 0.0,
         "inversion_sd": 0.1,
         "inversion_sd_deg": 5.0, "inversion_median": m, "inversion_q25": m, "inversion_q75": m}
        for w, m in ((1.0, 0.0), (2.0, 0.8))
    ]  # fmt: skip
    fig = plot_inversion(rows, "g")
    low, high = fig.axes[0].get_ylim()
    marker = 6 / 72 * fig.dpi  # a default marker's radius, in pixels, at most
    pixels_per_unit = fig.axes[0].bbox.height / (high - low)
    assert -low * pixels_per_unit >= marker / 2


def test_a_run_whose_test_and_selection_at_w_disagree_is_marked():
    # Issue 46 (8): runs at p 0.02 and 0.01 read "feedforward at W: no" with no note why.
    import pyarrow as pa

    from hcid import tables
    from hcid.report.run_table import run_table as _run_table

    base = {n: None for n in tables.ANALYSIS.names}
    numbers = {n: float("nan") for n, t in tables.ANALYSIS.fields if t == pa.float64()}
    row = {**base, **numbers, "run_id": 1, "method": "direct", "decided_by": "W*", "nb_ft": 0,
           "uncertain": False, "p_value": 0.02, "fc_dof": 0, "fc_p": float("nan")}  # fmt: skip
    row.update(
        {
            f"{p}_status": "determined"
            for p in ("Kpt", "TI", "tau_pt", "Kpe", "TL", "tau_pe", "w_nms", "zeta_nms")
        }
    )
    runs = [
        {**row, "run_id": 1, "evidence": "feedforward", "feedforward_at_w": False},
        {**row, "run_id": 2, "evidence": "feedforward", "feedforward_at_w": True},
    ]
    header, rows = _run_table(pa.Table.from_pylist(runs))
    at_w = header.index("feedforward at W")
    assert [r[at_w] for r in rows] == ["no *", "yes"]


def test_a_calibration_no_method_uses_is_captioned_as_such():
    # Issue 46 (3): the compensatory own twins' caption said "used for no method" and then
    # described a safe interval and a recommended W for both methods.
    from hcid.report.sections.study import _calibration_caption

    unused = _calibration_caption(
        "c, twins of its own fitted model, used for no method", ["direct", "indirect"], {}, False
    )
    assert "safe interval" not in unused and "no method's W comes from these twins" in unused
    used = _calibration_caption("c, used for direct", ["direct", "indirect"], {"indirect": 0.02}, True)
    assert "direct: the safe interval" in used and "indirect: the W used, the least total error" in used


def test_a_calibration_figures_legends_stay_in_their_panels_and_a_narrow_interval_shows():
    # Issue 46 (3, the figure half): a narrow safe interval was a sliver hidden under the
    # recommended W's line (its edges are drawn now); the legends are checked to stay within their
    # panels (the issue saw an entry run off the figure; not reproduced on these rates).
    import pyarrow as pa

    from hcid.report.figures import plot_calibration

    w = np.geomspace(1e-3, 1.0, 61)
    rows = []
    for method, (lo, hi) in (("direct", (0.0072, 0.0075)), ("indirect", (float("nan"), float("nan")))):
        for x in w:
            rows.append(
                {"method": method, "w": x, "fp_rate": float(x < 0.007), "fp_low": 0.0, "fp_high": 0.2,
                 "fn_rate": float(x > 0.5), "fn_low": 0.0, "fn_high": 0.2, "safe_low": lo, "safe_high": hi,
                 "recommended": (lo * hi) ** 0.5 if lo == lo else float("nan"), "target_rate": 0.0,
                 "n_fb": 20, "n_ff": 20}
            )  # fmt: skip
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = plot_calibration(pa.Table.from_pylist(rows), "g", used={"indirect": 0.3})
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    for ax in fig.axes:
        box, panel = ax.get_legend().get_window_extent(renderer), ax.get_tightbbox(renderer)
        neighbours = [a.get_window_extent(renderer) for a in fig.axes if a is not ax]
        own = ax.get_window_extent(renderer)
        assert box.x0 >= fig.bbox.x0 and box.x1 <= fig.bbox.x1
        assert own.x0 - 20 <= box.x0 and box.x1 <= own.x1 + 20  # within its own panel's width
        assert not any(box.overlaps(n) for n in neighbours)
        assert panel is not None
    direct = fig.axes[0]
    edges = [line.get_xdata()[0] for line in direct.get_lines() if line.get_linestyle() == "--"]
    assert edges == pytest.approx([0.0072, 0.0075])  # the interval's edges drawn
