"""hcid report on configs/ci.yaml: built from the tables alone, valid figures, verdicts that follow."""

import os
import re
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from hcid.cli import app
from hcid.report import build_report
from hcid.report.build import compute_report

from .conftest import CI_CONFIG, ROOT, report_without_figures

runner = CliRunner()
FIGURES = (
    "forcing_spectra.png",
    "signals.png",
    "vaf_vs_w.png",
    "nb_ft_vs_w.png",
    "rates_vs_w.png",
    "bode_FB_bic.png",
    "bode_FF_bic.png",
    "bode_FF_w047.png",
    "errors_bic.png",
)


@pytest.fixture(scope="module")
def ci_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("report") / "ci"
    result = runner.invoke(app, ["run", str(CI_CONFIG), "--run", str(run), "--quiet"])
    assert result.exit_code == 0, result.output
    return run


@pytest.fixture(scope="module")
def report(ci_run):
    return build_report(ci_run)


def _png_size(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"  # PNG signature (RFC 2083)
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def test_every_figure_is_a_valid_png(report):
    names = {p.name for p in report.figures}
    assert names == set(FIGURES)
    for path in report.figures:
        width, height = _png_size(path)
        assert width >= 600 and height >= 300  # readable at page width


def test_report_from_tables_alone(ci_run, tmp_path):
    # Copy only the Parquet tables and config: no simulation is rerun, nothing else is read.
    only = tmp_path / "tables"
    only.mkdir()
    for p in list(ci_run.glob("*.parquet")) + [ci_run / "config.yaml"]:
        shutil.copy(p, only / p.name)
    result = build_report(only, tmp_path / "out")
    assert not result.missing
    md = (tmp_path / "out" / "report.md").read_text()
    for section in (
        "## 1. Run facts",
        "## 2. Simulation",
        "## 3. Model fit vs W",
        "## 4. Feedforward found",
        "## 5. Selected models at W_BIC",
        "## 6. FF feedback path",
        "## 7. Errors at W_BIC",
    ):
        assert section in md
    # The answer first: the paper's verdicts before every numbered section.
    assert md.index("## The answer: the paper's claims") < md.index("## 1. Run facts")
    html = (tmp_path / "out" / "report.html").read_text()
    assert html.count("data:image/png;base64,iVBOR") == len(FIGURES)  # embedded, self-contained


def test_verdict_rows_cover_spec_section_6(report):
    claims = [v.claim for v in report.verdicts]
    for fragment in (
        "RMS(e) FB",
        "RMS(e) FF",
        "VAF of selected models",
        "VAF collapses",
        "W_FP direct",
        "W_FP indirect",
        "FF mean nb_ft >= 2",
        "AIC and BIC below W_FP",
        "FB false positives at W_BIC",
        "FF feedforward at W_BIC accurate",
        "FF at W = 0.47: no feedforward",
        "leaky integrator",
        "errors at W_BIC",
    ):
        assert any(fragment in c for c in claims), fragment


def _verdict(report, claim):
    return next(v for v in report.verdicts if v.claim == claim)


def test_verdict_flips_with_threshold_table(ci_run, tmp_path):
    # The W_FP verdict follows from thresholds.parquet (SPEC 9 rule since issue 13): with
    # P(W_FP >= paper) = 0.5 the paper's value is consistent within sampling; with 0 it does not hold.
    run = tmp_path / "altered"
    shutil.copytree(ci_run, run)
    table = pq.read_table(run / "thresholds.parquet")
    rows = table.to_pylist()
    for p, holds in ((0.5, True), (0.0, False)):
        for r in rows:
            if r["method"] == "direct" and not r["has_feedforward"]:
                r["p_w_fp_at_paper"] = p
        pq.write_table(pa.Table.from_pylist(rows, schema=table.schema), run / "thresholds.parquet")
        verdict = _verdict(compute_report(run), "W_FP direct")  # the verdicts, without drawing
        assert verdict.holds is holds
        assert f"P(W_FP >= 0.012) = {p:.3g}" in verdict.this_run


def test_partial_run_reports_what_is_there(tmp_path):
    run = tmp_path / "partial"
    result = runner.invoke(app, ["simulate", str(CI_CONFIG), "--run", str(run), "--quiet"])
    assert result.exit_code == 0
    result = runner.invoke(app, ["report", str(run)])
    assert result.exit_code == 0, result.output
    assert "missing stages: identification, W sweep" in result.output
    md = (run / "report" / "report.md").read_text()
    assert "Missing: `frontier.parquet`" in md
    assert (run / "report" / "signals.png").is_file()


def test_report_of_non_run_dir_exit_2(tmp_path):
    result = runner.invoke(app, ["report", str(tmp_path / "nothing")])
    assert result.exit_code == 2
    assert "nothing: missing; make it first with `hcid run CONFIG`" in result.stderr
    (tmp_path / "nothing").mkdir()
    result = runner.invoke(app, ["report", str(tmp_path / "nothing")])
    assert result.exit_code == 2
    assert "config.yaml: missing" in result.stderr


#: Appended to a copy of report.html: after load, the page's title says how many images loaded.
_IMAGE_PROBE = """<script>
window.addEventListener("load", () => {
  const imgs = Array.from(document.images);
  const ok = imgs.filter((i) => i.complete && i.naturalWidth > 0).length;
  document.title = `images ${ok} of ${imgs.length}`;
});
</script>"""


#: Appended to a copy of report.html: after load, the title lists every table or figure wider
#: than the page at the window's width (a table's scroll box scrolling, an element past the edge).
_WIDTH_PROBE = """<script>
window.addEventListener("load", () => {
  const page = document.documentElement.clientWidth, out = [];
  document.querySelectorAll(".wide").forEach((box) => {
    const head = (box.querySelector("th") || {}).textContent;
    if (box.scrollWidth > box.clientWidth + 1) out.push("table " + head);
  });
  document.querySelectorAll("img, table").forEach((e) => {
    if (e.getBoundingClientRect().right > page + 1) out.push(e.tagName);
  });
  document.title = "wider than the page: " + out.length + " " + out.join("; ");
});
</script>"""


def wider_than_the_page(html: Path, tmp_path: Path, width: int = 1400) -> str | None:
    """What of ``html`` is wider than a ``width`` px window in headless Chromium ('0 ' for
    nothing), or None without Chromium (CI has it: HCID_REQUIRE_BROWSER)."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        if os.environ.get("HCID_REQUIRE_BROWSER"):
            pytest.fail("Chromium is not installed, and HCID_REQUIRE_BROWSER is set (CI)")
        return None
    probe = tmp_path / "width_probe.html"
    probe.write_text(html.read_text().replace("</body>", _WIDTH_PROBE + "</body>"))
    flags = ["--headless", "--no-sandbox", "--disable-gpu", f"--user-data-dir={tmp_path / 'width_profile'}",
             f"--window-size={width},3000", "--virtual-time-budget=10000"]  # fmt: skip
    proc = subprocess.run(
        [chromium, *flags, "--dump-dom", probe.as_uri()], capture_output=True, text=True, timeout=120
    )
    found = re.search(r"<title>wider than the page: (.*?)</title>", proc.stdout, re.S)
    assert found, proc.stdout[:300]
    return found.group(1)


def test_html_opens_in_headless_chromium(report, tmp_path):
    # A real browser opens report.html and every figure loads (an <img> that failed to load
    # has naturalWidth 0). CI installs Chromium (.ci/run) and sets HCID_REQUIRE_BROWSER, so
    # there the test cannot skip.
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        if os.environ.get("HCID_REQUIRE_BROWSER"):
            pytest.fail("Chromium is not installed, and HCID_REQUIRE_BROWSER is set (CI)")
        pytest.skip("Chromium is not installed")
    probe = tmp_path / "probe.html"  # the figures are data: URIs, so the copy can live anywhere
    probe.write_text(report.html.read_text().replace("</body>", _IMAGE_PROBE + "</body>"))
    flags = [
        "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic",
        f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=10000",
    ]  # fmt: skip
    proc = subprocess.run(
        [chromium, *flags, "--dump-dom", probe.as_uri()], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr[-500:]
    n_figures = report.html.read_text().count("<img")
    assert n_figures == len(FIGURES)
    assert f"<title>images {n_figures} of {n_figures}</title>" in proc.stdout, proc.stdout[:300]
    shot = tmp_path / "shot.png"
    proc = subprocess.run(
        [chromium, *flags, "--window-size=1200,3000", f"--screenshot={shot}", report.html.as_uri()],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-500:]
    _png_size(shot)
    assert wider_than_the_page(report.html, tmp_path) == "0 "  # issue 46: nothing past the page


def test_plots_draw_on_given_axes_and_colour_marks_by_method(ci_run):
    # STYLE 9: plot_*(data, ax=None) draws on the caller's axes. W marks take their
    # method's colour ("indirect" must not match "direct").
    import matplotlib.pyplot as plt

    from hcid.report import compute, figures

    curves = compute.compute_curves(pq.read_table(ci_run / "selection.parquet"))
    fig, ax = plt.subplots()
    out = figures.plot_nb_ft(curves, {"W_FP direct": 0.01, "W_FP indirect": 0.02}, ax=ax)
    assert out is fig
    colours = {line.get_label(): line.get_color() for line in ax.get_lines()}
    assert colours["W_FP direct"] == figures.method_color("direct") == "C0"
    assert colours["W_FP indirect"] == figures.method_color("indirect") == "C1"
    plt.close(fig)


# --------------------------------------------------------------------------- other experiments (issue 11)


def test_report_of_another_experiment(tmp_path):
    # An integrator plant with the disturbance at its input and a ramp target: the report shows
    # the experiment (plant, disturbance point, forcing functions and their spectra) and leaves
    # out the paper's verdicts and Table 2 column; the paper's ci run keeps them (test above).
    import yaml

    raw = yaml.safe_load(CI_CONFIG.read_text())
    raw["name"] = "ramps"
    raw["seeds"] = [1]
    raw["models"] = {
        "FB": {"Kpt": 0.0, "Kpe": 2.0, "TL": 0.0, "tau_pe": 0.25},
        "FF": {"Kpt": 0.8, "TI": 0.2, "tau_pt": 0.2, "Kpe": 2.0, "TL": 0.0, "tau_pe": 0.25},
    }
    del raw["loop"]["Kc"], raw["loop"]["wb"]
    raw["loop"].update(plant={"kind": "integrator", "K": 1.5}, disturbance_at="input")
    raw["signals"]["target"] = {
        "gain_deg": 5.0,
        "segments": [["c", 5, 0], ["r", 20, 1], ["c", 10, 0], ["r", 20, -1]],
    }
    config = tmp_path / "ramps.yaml"
    config.write_text(yaml.safe_dump(raw, sort_keys=False))
    run = tmp_path / "run"
    result = runner.invoke(app, ["run", str(config), "--run", str(run), "--quiet"])
    assert result.exit_code == 0, result.output
    assert "2.43" not in result.output  # no paper column for another experiment
    text, _ = report_without_figures(run, draw=["forcing_spectra.png"], out=tmp_path)
    assert "## Experiment" in text and "1.5/s (integrator)" in text
    assert "at the plant input: theta = Yc (u + fd)" in text
    assert "segments: 2 hold, 2 ramp" in text
    assert "The answer: the paper's claims" not in text and compute_report(run).verdicts == []
    assert "W_FP 0.012" not in text and "W_FN 0.26" not in text  # the paper's thresholds
    # Nor its figure numbers, its Table 2 column or the sampling test of its thresholds
    # (a newcomer's walkthrough, 2026-11-27, found all three in the integrator example's report).
    assert "paper Fig" not in text and "paper Table 2" not in text and "P(W_FP &gt;=" not in text
    assert "P*(W_FN &gt;=" not in text
    assert (tmp_path / "forcing_spectra.png").stat().st_size > 0


def test_paper_report_names_the_paper_experiment(report):
    text = report.markdown.read_text()
    assert "The paper's experiment" in text and "at the plant output: theta = Yc u + fd" in text
    assert "The answer: the paper's claims" in text
    assert "## 3. Model fit vs W (paper Fig. 5)" in text and "paper Table 2" in text
    assert "P(W_FP &gt;= 0.012)" in text  # Markdown escapes >
    numbers = [int(m) for m in re.findall(r"^## (\d+)[a-z]?\. ", text, flags=re.M)]
    assert numbers == sorted(numbers) and set(numbers) == set(range(1, max(numbers) + 1))  # no gap


# --------------------------------------------------------------------------- sampling verdicts (SPEC 9)


def _fb_thresholds(extents_by_method: dict, n_study: int = 50):
    """thresholds rows as sweep-w writes them, from given per-realization L of FB."""
    import pyarrow as pa

    from hcid import tables
    from hcid.config import paper
    from hcid.selection import over_w

    rows = []
    for method, extents in extents_by_method.items():
        rows.append(
            {
                "method": method,
                "model": "FB",
                "has_feedforward": False,
                "n_realizations": len(extents),
                "nf": 960,
                "w_fp": float(max(extents)),
                "w_fn": None,
                "p_w_fp_at_paper": over_w.threshold_exceedance(extents, paper.W_FP[method], n_study),
            }
        )
    return pa.Table.from_pylist(rows, schema=tables.thresholds().arrow)


def test_w_fp_verdict_by_the_sampling_rule(ci_config):
    # Constructed per-realization L (200 FB realizations) whose answer is known:
    # direct: 10 of 200 reach the paper's 0.012 -> P = 1 - 0.95^50 = 0.923: consistent within sampling;
    # indirect: none reaches 0.037 (all L <= 0.0115) -> P = 0: does not hold, whatever the factor.
    from hcid.report.verdicts import CONSISTENT, compute_verdicts

    direct = np.concatenate([np.zeros(150), np.full(40, 0.005), np.full(10, 0.013)])
    indirect = np.concatenate([np.zeros(186), np.full(14, 0.0115)])
    th = _fb_thresholds({"direct": direct, "indirect": indirect})
    verdicts = {v.claim: v for v in compute_verdicts(ci_config, None, None, th, None, None)}
    d, i = verdicts["W_FP direct"], verdicts["W_FP indirect"]
    assert d.holds is True and d.status_text == CONSISTENT
    assert "P(W_FP >= 0.012) = 0.923" in d.this_run
    assert i.holds is False and i.status_text == "does not hold"
    assert "P(W_FP >= 0.037) = 0" in i.this_run
    # A paper value far below every realization's L is implausible too: P = 1 > 0.975.
    th = _fb_thresholds({"direct": np.full(200, 0.05), "indirect": indirect})
    verdicts = {v.claim: v for v in compute_verdicts(ci_config, None, None, th, None, None)}
    assert verdicts["W_FP direct"].holds is False


def test_w_fn_verdict_by_the_bootstrap_interval(ci_config):
    # The paper's 0.26 inside both methods' bootstrap intervals: consistent; outside one: does not hold.
    from hcid import tables
    from hcid.report.verdicts import CONSISTENT, compute_verdicts

    def table(direct, indirect):
        rows = [
            {
                "method": me,
                "model": "FF",
                "has_feedforward": True,
                "n_realizations": 200,
                "nf": 960,
                "w_fp": None,
                "w_fn": (lo + hi) / 2,
                "w_fn_low": lo,
                "w_fn_high": hi,
                "p_w_fn_at_paper": p,
            }
            for me, (lo, hi, p) in (("direct", direct), ("indirect", indirect))
        ]
        return pa.Table.from_pylist(rows, schema=tables.thresholds().arrow)

    def verdicts(th):
        return {v.claim: v for v in compute_verdicts(ci_config, None, None, th, None, None)}

    inside = verdicts(table((0.22, 0.30, 0.4), (0.2, 0.27, 0.1)))
    for me in ("direct", "indirect"):
        assert inside[f"FF mean nb_ft >= 2, {me}"].holds is True
        assert inside[f"FF mean nb_ft >= 2, {me}"].status_text == CONSISTENT
    assert "P*(W_FN >= 0.26) = 0.1" in inside["FF mean nb_ft >= 2, indirect"].this_run
    outside = verdicts(table((0.22, 0.30, 0.4), (0.4, 0.6, 1.0)))["FF mean nb_ft >= 2, indirect"]
    assert outside.holds is False and outside.status_text == "does not hold"


# --------------------------------------------------------------------------- report folders (issue 24)


def test_report_out_follows_the_run_directory_rules(ci_run, tmp_path):
    # Before: --out wrote into any folder, replacing a user's report.md; --out / wrote 11 files
    # into /. Now: new, empty or hcid's own report folder only (hcid.io.folders).
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "report.md").write_text("my own notes\n")
    for out, message in (
        (mine, "not an hcid report (no hcid-run.json, and it holds other files)"),
        (tmp_path.anchor, "refusing to use it as a report folder"),
        (ci_run / "config.yaml", "not a directory"),
    ):
        result = runner.invoke(app, ["report", str(ci_run), "--out", str(out)])
        assert result.exit_code == 2 and message in result.stderr, result.output
        assert len(result.stderr.strip().splitlines()) == 1
    assert (mine / "report.md").read_text() == "my own notes\n" and sorted(os.listdir(mine)) == ["report.md"]
    assert runner.invoke(app, ["report", str(ci_run), "--out", str(ci_run)]).exit_code == 2  # a run directory


def test_report_folder_is_reused_and_keeps_user_files(ci_run, report, tmp_path):
    out = tmp_path / "rep"
    shutil.copytree(ci_run / "report", out)  # a report hcid wrote (the module's), its manifest with it
    (out / "notes.txt").write_text("mine")
    (out / "stale.png").write_bytes(b"mine too")  # not listed in the manifest: not hcid's
    assert runner.invoke(app, ["report", str(ci_run), "--out", str(out)]).exit_code == 0
    assert (out / "notes.txt").read_text() == "mine" and (out / "stale.png").read_bytes() == b"mine too"
    assert set(FIGURES) <= set(os.listdir(out))


@pytest.mark.parametrize("n_sets", [1, 2, 6])
def test_each_run_has_its_own_row_named_on_the_axis(n_sets):
    # Issue 46 (2): numbers beside markers in stacked clusters ("10 / 23 24 / 22 6 12" over five
    # diamonds) were not read as whose they are. Each run has a row of its own, its name the y
    # tick label at its marker's height (measured in pixels), no two names overlap, and every name
    # prints inside the figure; fourteen runs per set with W* so close their markers touch.
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from hcid.report.figures_hcfit import plot_evidence

    rng = np.random.default_rng(3)
    sets = range(1, n_sets + 1)
    twins = [
        {"forcing_set": fs, "twin": twin, "w_star": w}
        for fs in sets
        for twin, scale in (("FB", 0.1), ("FF", 0.4))
        for w in scale * np.exp(rng.normal(0, 0.3, 20))
    ]
    runs = [
        {"forcing_set": fs, "run_id": 10 + k + 14 * fs, "w_star": 0.1 * 1.004 ** (k * (fs * k % 5)),
         "p_w_star": 0.2}
        for fs in sets
        for k in range(14)
    ]  # fmt: skip
    runs = [{**r, "label": f"run {r['run_id']}: S{r['run_id'] % 7}, trial {r['run_id'] % 3}"} for r in runs]
    fig = plot_evidence(twins, runs, "clustered runs")
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    ax = fig.axes[0]
    ticks = {t.get_text(): t for t in ax.get_yticklabels() if t.get_visible()}
    diamonds = [line for line in ax.lines if line.get_marker() == "D" and len(line.get_xdata())]
    assert len(diamonds) == len(runs)
    page = fig.bbox
    for r, line in zip(runs, diamonds, strict=True):
        label = ticks[r["label"]]
        box = label.get_window_extent(renderer)
        _, y = ax.transData.transform(line.get_xydata()[0])
        assert box.y0 <= y <= box.y1, (r["label"], box, y)
        assert page.x0 <= box.x0 and box.x1 <= page.x1 and page.y0 <= box.y0 and box.y1 <= page.y1
    boxes = sorted((t.get_window_extent(renderer) for t in ticks.values()), key=lambda b: b.y0)
    for a, b in zip(boxes, boxes[1:], strict=False):
        assert a.y1 <= b.y0, (a, b)


@pytest.mark.parametrize("low", [1e-4, 5e-4, 0.02])
def test_the_w_axis_labels_print_clear_of_each_other(low):
    # W* from the grid's smallest W (1e-4) to 0.8, as on the CPHS fo plant, and narrower spans:
    # 1-2-5 ticks over four decades printed 0.0001 into 0.0002; one per decade there.
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from hcid.report.figures_hcfit import plot_evidence

    twins = [{"forcing_set": 1, "twin": t, "w_star": w} for t in ("FB", "FF") for w in (low, 0.8)]
    runs = [{"forcing_set": 1, "run_id": 1, "w_star": 0.1, "p_w_star": 0.2}]
    fig = plot_evidence(twins, runs)
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    labels = [t for t in fig.axes[0].get_xticklabels() if t.get_visible() and t.get_text()]
    assert len(labels) >= 3
    boxes = sorted((t.get_window_extent(renderer) for t in labels), key=lambda b: b.x0)
    for a, b in zip(boxes, boxes[1:], strict=False):
        assert a.x1 + 2 <= b.x0, (a, b)


def test_a_variant_is_summarised_from_its_own_tables(ci_run):
    # hcid.report.variants (make indirect-variants) had no test: on the ci run (3 seeds), its W_FP
    # is thresholds.parquet's indirect FB row, no block of 50 realizations is complete, the most
    # frequent stage-1 structure among the FB realizations is counted, and the rates are the FB
    # twin's under the indirect method.
    from hcid.assembly.resolve import load_config
    from hcid.report.variants import compute_variant

    variant = compute_variant(load_config(CI_CONFIG), ci_run)
    rows = pq.read_table(ci_run / "thresholds.parquet").to_pylist()
    fb = next(r for r in rows if r["method"] == "indirect" and r["model"] == "FB")
    assert (variant.n, variant.w_fp, variant.block_w_fp) == (3, fb["w_fp"], ())
    columns = ("na", "nb_ft", "nb_fd", "nk_ft", "nk_fd")
    chosen = [tuple(r[c] for c in columns) for r in pq.read_table(ci_run / "stage1.parquet").to_pylist()
              if r["model"] == "FB"]  # fmt: skip
    assert int(variant.stage1_top.rsplit(" x", 1)[1]) == max(chosen.count(s) for s in chosen)
    assert set(variant.rates.column("model").to_pylist()) == {"FB"}
    assert set(variant.rates.column("method").to_pylist()) == {"indirect"}


# ------------------------------------------------------------- a newcomer's walkthrough (2026-11-27)


def test_report_text_renders_emphasis_and_literal_asterisks():
    from hcid.report.document import _inline_md

    html = _inline_md("*Words used here.* A run's **W\\*** is ... reach its W\\*; x * y * z")
    assert html.startswith("<i>Words used here.</i> A run's <b>W*</b>")
    assert "\\" not in html and "reach its W*;" in html and "x * y * z" in html


def test_a_value_on_its_bound_at_zero_reads_as_zero():
    import math

    from hcid.report.run_table import with_se as _with_se

    row = {"TL": 1.69e-08, "TL_status": "at a search bound (0)", "TL_se": math.nan}
    assert _with_se(row, "TL") == "0†"
    row = {"TL": 0.25, "TL_status": "at a search bound (0.25)", "TL_se": math.nan}
    assert _with_se(row, "TL") == "0.25†"
    row = {"Kpt": 5e-7, "Kpt_status": "correlated with TI (0.97)", "Kpt_se": math.nan}
    assert _with_se(row, "Kpt") == "5e-07†"  # not on a bound: its value as it is


def test_a_measured_study_of_another_plant_has_no_paper_labels(tmp_path):
    config, run = ROOT / "configs" / "lab_example.yaml", tmp_path / "lab"
    data = ROOT / "configs" / "lab_example" / "S1_pursuit_trial1.csv"
    result = runner.invoke(app, ["identify", str(config), "--data", str(data), "--run", str(run), "--quiet"])
    assert result.exit_code == 0, result.output
    assert runner.invoke(app, ["sweep-w", str(config), "--run", str(run)]).exit_code == 0
    text, _ = report_without_figures(run)
    assert "## 3. Model fit vs W" in text and "paper Fig" not in text


def test_the_run_table_is_split_in_two_that_fit_a_page():
    """A re-check found the run table (21 columns for the recordings) wider than the page, its
    last columns behind a scroll bar: the run's evidence and fit, then its parameters."""
    from hcid.report.run_table import split_runs as _split_runs

    header = [
        "run",
        "subject",
        "method",
        "p (evidence)",
        "Kpt",
        "TL s",
        "zeta_nms",
        "VAF %",
        "data check (p)",
    ]
    row = ["1", "dp", "direct", "0.01 (W*)", "0.9", "0.2", "0.35 (held)", "66.0", "0.39"]
    (h1, r1), (h2, r2) = _split_runs(header, [row])
    assert h1 == ["run", "subject", "method", "p (evidence)", "VAF %", "data check (p)"]
    assert h2 == ["run", "subject", "method", "Kpt", "TL s", "zeta_nms"]
    assert r1 == [["1", "dp", "direct", "0.01 (W*)", "66.0", "0.39"]] and r2 == [
        ["1", "dp", "direct", "0.9", "0.2", "0.35 (held)"]
    ]
