"""The methods: direct and indirect identification on a noise-free known ARX system, and the registry."""

import copy
import dataclasses

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml
from scipy import signal as sps

from hcid import methods
from hcid.assembly.resolve import parse_config
from hcid.errors import IdentificationError
from hcid.methods import Method, StageSpec, identify, registered, shift_forward
from hcid.pipeline import Execution
from hcid.selection import over_w

from .conftest import CI_CONFIG

# Known systems, both inside configs/ci.yaml's grids.
# Stage 1 (e from ft_s and fd): na 2, nb_ft 3 at nk 2, nb_fd 2 at nk 1.
A1, B11, B12, NK11, NK12 = [1.0, -1.2, 0.5], [0.3, -0.2, 0.1], [0.8, 0.4], 2, 1
# HC (u from ft_s and e): na 2, nb_ft 2 at nk 23, nb_e 3 at nk 5.
A2, B21, B22, NK21, NK22 = [1.0, -0.9, 0.2], [0.5, -0.3], [1.1, -0.6, 0.2], 23, 5


def _arx(a, b1, nk1, i1, b2, nk2, i2):
    x = sps.lfilter(np.concatenate([np.zeros(nk1), b1]), [1.0], i1)
    x += sps.lfilter(np.concatenate([np.zeros(nk2), b2]), [1.0], i2)
    return sps.lfilter([1.0], a, x)


@pytest.fixture(scope="module")
def settings():
    return parse_config(yaml.safe_load(CI_CONFIG.read_text()), "ci").identify


@pytest.fixture(scope="module")
def record(settings):
    rng = np.random.default_rng(7)
    n = 2048
    ft = rng.standard_normal(n)
    fd = rng.standard_normal(n)
    ft_s = shift_forward(ft, settings.shift_samples(25.0))
    e = _arx(A1, B11, NK11, ft_s, B12, NK12, fd)
    u = _arx(A2, B21, NK21, ft_s, B22, NK22, e)
    return {"ft": ft, "fd": fd, "e": e, "u": u}


@pytest.mark.parametrize("method", ["direct", "indirect"])
@pytest.mark.parametrize("w", [2.5, 4.0])
def test_noise_free_system_is_selected_exactly(record, settings, method, w):
    # An exact fit has V at rounding level (log V ~ -67 here) and exact
    # over-parametrised fits scatter by up to ~2 in log V (measured: 1.5), while every
    # model missing a true term has log V > -7 (d = 1: log V ~ -2). So for 2.5 <= W < ~8
    # (= (67 - 2) / (9 - 1)) the true model
    # (d = 9) is the selection.
    result = identify(record, settings, method, rate=25.0)
    fit = result.fit
    orders = np.column_stack([fit.na, fit.nb1, fit.nb2, fit.nk1, fit.nk2])
    row = over_w.select_at(fit.d, fit.v, orders, np.array([w]))[0]
    assert tuple(orders[row]) == (2, 2, 3, NK21, NK22)
    np.testing.assert_allclose(fit.a[row], A2, atol=1e-9)
    np.testing.assert_allclose(fit.b1[row], B21, atol=1e-9)
    np.testing.assert_allclose(fit.b2[row], B22, atol=1e-9)
    assert fit.vaf_validation[row] == pytest.approx(100.0, abs=1e-9)
    if method == "indirect":
        # Stage 1 reproduces e exactly, so its V is at rounding level.
        assert result.choices[0].v < 1e-20


def test_target_shift_is_one_second(settings):
    # SPEC 3: ft_s(k) = ft(k + 25), zeros after the record.
    x = np.arange(100.0)
    s = shift_forward(x, settings.shift_samples(25.0))
    assert s[0] == 25.0 and s[74] == 99.0 and np.all(s[75:] == 0.0)


def test_unknown_method_is_an_error(record, settings):
    from hcid.errors import IdentificationError

    with pytest.raises(IdentificationError, match="method: must be one of direct, indirect"):
        identify(record, settings, "both", rate=25.0)


def test_stage1_window_is_auto(settings):
    # SPEC 3: stage 1 estimates and validates from the grid's largest lag on. ci.yaml's
    # stage-1 grid: max(na 4, nk_ft 3 + nb_ft 8 - 1, nk_fd 3 + nb_fd 4 - 1) = 10.
    assert settings.stage("stage1").estimation.rows() == slice(10, 2048)
    assert settings.stage("stage1").validation.rows() == slice(10, 2048)


def test_dropped_input_does_not_count_in_max_lag():
    # An input with nb_hi = 0 is dropped, so its delays do not push the window.
    raw = yaml.safe_load(CI_CONFIG.read_text())
    raw["identify"]["stage1"].update(nb2=[0, 0], nk2=[1, 150])
    cfg = parse_config(copy.deepcopy(raw), "ci")
    assert cfg.identify.stage("stage1").estimation.rows() == slice(10, 2048)


@pytest.mark.parametrize("method", ["direct", "indirect"])
@pytest.mark.parametrize("w", [7.153e-3, 0.1])
def test_nearly_noise_free_system_is_selected_at_small_w(record, settings, method, w):
    # With white noise of 1e-6 of std(u) on u, log V is meaningful (no rounding scatter):
    # from W_BIC (SPEC 4: 7.15e-3) on, the true orders and delays are selected, and the
    # coefficients come back to within ~1e-6 (measured 1e-7). Below W_BIC (at W_AIC) an
    # extra nb_ft term fitting the noise wins, as the paper's AIC finding would suggest.
    rng = np.random.default_rng(8)
    noisy = dict(record, u=record["u"] + 1e-6 * np.std(record["u"]) * rng.standard_normal(2048))
    fit = identify(noisy, settings, method, rate=25.0).fit
    orders = np.column_stack([fit.na, fit.nb1, fit.nb2, fit.nk1, fit.nk2])
    row = over_w.select_at(fit.d, fit.v, orders, np.array([w]))[0]
    assert tuple(orders[row]) == (2, 2, 3, NK21, NK22)
    np.testing.assert_allclose(fit.a[row], A2, atol=1e-5)
    np.testing.assert_allclose(fit.b2[row], B22, atol=1e-5)


# --------------------------------------------------------------------------- the registry seam


def _toy_run(record, settings, shift, threads):
    import time

    from hcid.methods.base import MethodResult, fit_stage

    start = time.perf_counter()
    fit = fit_stage(
        settings.stage("toy"), shift_forward(record["ft"], shift), record["e"], record["u"], threads
    )
    return MethodResult("toy", fit, (), time.perf_counter() - start)


TOY = Method(
    name="toy",
    stages=(
        StageSpec(
            "toy",
            ("ft", "e", "u"),
            {
                "na": [1, 2],
                "nb1": [0, 2],
                "nb2": [0, 2],
                "nk1": [24, 26],
                "nk2": [5, 6],
                "estimation": [201, 1088],
                "validation": [1089, 2048],
            },
        ),
    ),
    run=_toy_run,
)


def test_a_registered_method_flows_through_to_the_selection_tables(ci_raw, tmp_path):
    # The seam of issue 9: one Method object, registered, is parsed, identified, swept and
    # tabulated with nothing else changed. Its Nf is its own stage's estimation rows: 888.
    from hcid.pipeline import identify_study, sweep_study

    with registered(TOY):
        cfg = parse_config(ci_raw, "toy")
        assert cfg.identify.stage("toy").estimation.length == 888
        run = tmp_path / "toy"
        identify_study(cfg, run, ("toy",), execution=Execution(1, progress=False))
        sweep = sweep_study(cfg, run)
    selection = pq.read_table(run / "selection.parquet")
    assert set(selection.column("method").to_pylist()) == {"toy"}
    assert selection.num_rows == 2 * len(cfg.selection.w_grid)  # FB and FF, seed 1
    th = {(r["method"], r["model"]): r for r in sweep.thresholds.to_pylist()}
    assert th[("toy", "FB")]["nf"] == 888
    assert th[("toy", "FB")]["w_bic"] == pytest.approx(np.log(888) / 888, rel=1e-12)
    assert "toy" not in methods.METHODS  # unregistered on leaving the block


def test_nf_follows_each_methods_own_final_stage(ci_raw, tmp_path):
    # The latent bug of issue 9: with stage 2's estimation rows differing from direct's, the
    # indirect method's W_AIC/W_BIC follow stage 2's Nf (SPEC 7), in the table and the report.
    from hcid.pipeline import run_study
    from hcid.report.build import compute_report

    ci_raw["identify"]["stage2"]["estimation"] = [201, 1088]
    cfg = parse_config(ci_raw, "nf")
    run = tmp_path / "nf"
    result = run_study(cfg, run, execution=Execution(1, progress=False))
    th = {(r["method"], r["model"]): r for r in result.sweep.thresholds.to_pylist()}
    assert th[("direct", "FB")]["nf"] == 960 and th[("indirect", "FB")]["nf"] == 888
    assert th[("indirect", "FF")]["w_bic"] == pytest.approx(np.log(888) / 888, rel=1e-12)
    assert th[("direct", "FF")]["w_bic"] == pytest.approx(np.log(960) / 960, rel=1e-12)
    data = compute_report(run)
    assert data.run.w_bic() == pytest.approx({"direct": np.log(960) / 960, "indirect": np.log(888) / 888})
    marks = data.sections["curves"].criterion_marks
    assert marks["W_BIC direct"] == pytest.approx(np.log(960) / 960)
    assert marks["W_BIC indirect"] == pytest.approx(np.log(888) / 888)


def test_final_signals_rebuild_what_the_final_stage_was_fitted_to(ci_config, paper_record):
    # Source: the identification itself. Refitting the final stage's grid on the rebuilt
    # (i1, i2, o) gives the frontier that identify returned: for the indirect method, e_r
    # comes from stage 1's stored choice refitted alone (its V checked against the stored
    # one), so V agrees to the engine's rounding (fit_grid Notes: ~1e-9 relative).
    from hcid.methods.base import fit_stage

    settings = ci_config.identify
    shift = settings.shift_samples(ci_config.timing.output_rate)
    for name in ("direct", "indirect"):
        method = methods.get(name)
        result = identify(paper_record, settings, name, rate=25.0)
        i1, i2, o = method.final_signals(paper_record, settings, shift, result.choices)
        np.testing.assert_array_equal(i1, paper_record["ft_s"])
        np.testing.assert_array_equal(o, paper_record["u"])
        again = fit_stage(settings.stage(method.final_stage.name), i1, i2, o, 1)
        np.testing.assert_allclose(again.v, result.fit.v, rtol=1e-6)
    # A choice made on another record is refused instead of giving a wrong e_r.
    wrong = dataclasses.replace(result.choices[0], v=result.choices[0].v * 1.01)
    with pytest.raises(IdentificationError, match="stage1: refitting the chosen candidate"):
        methods.get("indirect").final_signals(paper_record, settings, shift, (wrong,))


# --------------------------------------------------------------------------- stage-1 options


def _with_stage1(ci_raw, **options):
    raw = copy.deepcopy(ci_raw)
    raw["identify"]["stage1"].update(options)
    return parse_config(raw, "variant")


def test_stage1_zero_initial_fixed_matches_the_reference_on_every_sample(record, ci_raw):
    # rows: zero_initial fits and validates on all 2048 samples with zero regressors before the
    # record; model: fixed fits only fixed_orders. Source of truth: the plain lstsq + lfilter
    # twin (hcid.arx.reference) on the same rows, with e made noisy so the fit is not exact.
    from .naive import fit_reference

    rng = np.random.default_rng(11)
    noisy = dict(record, e=record["e"] + 0.05 * rng.standard_normal(record["e"].size))
    cfg = _with_stage1(ci_raw, rows="zero_initial", model="fixed", fixed_orders=[2, 3, 2, 2, 1])
    result = identify(noisy, cfg.identify, "indirect", rate=25.0)
    choice = result.choices[0]
    assert (choice.na, choice.nb1, choice.nb2, choice.nk1, choice.nk2) == (2, 3, 2, 2, 1)
    assert choice.n_candidates == 1
    ft_s = shift_forward(noisy["ft"], 25)
    every = slice(0, 2048)
    ref = fit_reference(ft_s, noisy["fd"], noisy["e"], 2, 3, 2, 2, 1, every, every)
    assert choice.v == pytest.approx(float(ref.v[0]), rel=1e-8)
    # The default (rows from the grid's largest lag, best of the grid) is another fit.
    default = identify(noisy, parse_config(ci_raw, "d").identify, "indirect", rate=25.0).choices[0]
    assert default.n_candidates > 1 and default.v != pytest.approx(choice.v, rel=1e-6)


def test_stage1_options_are_checked_and_kept_out_of_a_default_config(ci_raw):
    from hcid.errors import ConfigError

    with pytest.raises(ConfigError, match=r"identify\.stage1\.rows: must be one of auto, zero_initial"):
        _with_stage1(copy.deepcopy(ci_raw), rows="all")
    with pytest.raises(ConfigError, match=r"identify\.stage1\.fixed_orders: must be \[na, nb_ft"):
        _with_stage1(copy.deepcopy(ci_raw), fixed_orders=[0, 2, 2, 6, 6])
    default = parse_config(copy.deepcopy(ci_raw), "d")
    assert default.identify.stage("stage1").options == ()
    assert "rows" not in default.to_yaml() and "fixed_orders" not in default.to_yaml()
    stated = _with_stage1(copy.deepcopy(ci_raw), rows="auto", model="best")  # the defaults, stated
    assert stated.to_yaml() == default.to_yaml().replace("name: d", "name: variant")


def test_a_stage1_variant_on_the_ci_config_flows_to_its_tables_and_report(ci_raw, tmp_path):
    # configs/ci.yaml (seed 1) with stage 1 on every sample and the authors' fixed orders: the
    # stage-1 table holds those orders, handoff.parquet the VAF of e_r against the noise-free e,
    # the resolved config the options, and the report's facts name them.
    from hcid.pipeline import identify_study, sweep_study
    from hcid.report.build import compute_report

    cfg = _with_stage1(ci_raw, rows="zero_initial", model="fixed", fixed_orders=[4, 2, 2, 6, 6])
    run = tmp_path / "variant"
    identify_study(cfg, run, ("indirect",), execution=Execution(1, progress=False))
    sweep_study(cfg, run)
    stage1 = pq.read_table(run / "stage1.parquet").to_pylist()
    assert {(r["na"], r["nb_ft"], r["nb_fd"], r["nk_ft"], r["nk_fd"]) for r in stage1} == {(4, 2, 2, 6, 6)}
    handoff = pq.read_table(run / "handoff.parquet").to_pylist()
    assert {(r["model"], r["stage"], r["signal"]) for r in handoff} == {
        ("FB", "stage1", "e"),
        ("FF", "stage1", "e"),
    }
    assert all(50.0 < r["vaf_noise_free"] <= 100.0 for r in handoff)
    assert all(r["vaf_noise_free_record"] <= 100.0 for r in handoff)
    assert "rows: zero_initial" in (run / "config.yaml").read_text()
    data = compute_report(run)
    facts = dict(data.sections["facts"])
    assert (
        "rows zero_initial, model fixed, fixed_orders (4, 2, 2, 6, 6)" in facts["indirect: stage stage1 grid"]
    )
    assert data.sections["handoff"] is not None


def test_a_new_method_touches_no_existing_run_or_unrelated_config(ci_raw, tmp_path):
    # Issue 25: the stages are resolved for the methods a command uses. A run made before a
    # method is registered re-opens unchanged (sweep-w, fit-hc's reading, report), and a
    # method whose defaults do not fit a config stops only the commands that use it.
    import dataclasses

    import yaml
    from typer.testing import CliRunner

    from hcid.cli import app
    from hcid.errors import ConfigError

    config = tmp_path / "ci.yaml"
    raw = dict(ci_raw, seeds=[1])
    config.write_text(yaml.safe_dump(raw))
    run = tmp_path / "run"
    runner = CliRunner()
    made = runner.invoke(app, ["identify", str(config), "--run", str(run), "--method", "direct", "--quiet"])
    assert made.exit_code == 0, made.output
    assert runner.invoke(app, ["sweep-w", str(config), "--run", str(run)]).exit_code == 0
    recorded = (run / "config.yaml").read_text()
    tables_before = {p.name: p.read_bytes() for p in run.glob("*.parquet")}
    # The toy's validation window ends beyond this config's 2048 samples: it cannot be resolved here.
    spec = TOY.stages[0]
    bad = dataclasses.replace(TOY, stages=(dataclasses.replace(spec, defaults={**spec.defaults,
                              "validation": [1089, 4096]}),))  # fmt: skip
    with registered(bad):
        assert parse_config(raw, "ci", method_names=("direct",)).identify.stage("direct")
        with pytest.raises(ConfigError, match="identify.toy.validation"):
            parse_config(raw, "ci")  # every method, the toy included
        for argv in (["sweep-w", str(config), "--run", str(run)], ["report", str(run)]):
            result = runner.invoke(app, argv)
            assert result.exit_code == 0, result.output
        result = runner.invoke(
            app, ["identify", str(config), "--run", str(run), "--method", "direct", "--quiet"]
        )
        assert result.exit_code == 0 and "identified 0 realization-methods, reused 2" in result.output
    assert (run / "config.yaml").read_text() == recorded
    assert {p.name: p.read_bytes() for p in run.glob("*.parquet")} == tables_before
