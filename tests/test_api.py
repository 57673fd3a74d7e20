"""The public API (hcid.api): from a file to a fitted HC model, checked against the engine."""

import re

import numpy as np
import pyarrow.parquet as pq
import pytest

import hcid
from hcid import methods
from hcid.arx.response import path_response
from hcid.arx.simulation import simulate
from hcid.methods import shift_forward
from hcid.selection import over_w

from .conftest import CI_CONFIG, ROOT

EXAMPLE = ROOT / "configs" / "example_data" / "subject_synthetic.csv"
COLUMNS = {"run": "trial", "time": "time_s", "ft": "target", "fd": "disturbance", "e": "error", "u": "stick"}


@pytest.fixture(scope="module")
def record():
    return hcid.read_records(EXAMPLE, columns=COLUMNS)[1]


@pytest.fixture(scope="module")
def lab_record():
    """Run 1 of a lab example file (multisines over its 40 s window), as configs/lab_example.yaml
    reads it: its columns, 20 Hz, 5 s lead-in, the window's 800 samples."""
    columns = {"time": "time", "ft": "target", "fd": "disturbance", "e": "error", "u": "stick"}
    path = ROOT / "configs" / "lab_example" / "S1_pursuit_trial1.csv"
    ((run, whole),) = hcid.read_records(path, columns=columns, rate=20.0, lead_in=5.0).items()
    return hcid.Record(run, 20.0, *(getattr(whole, k)[:800] for k in ("t", "ft", "fd", "e", "u")))


@pytest.fixture(scope="module")
def direct(record):
    return hcid.identify(record, "direct")


def test_public_names_and_version():
    assert hcid.__version__ and "identify" in hcid.__all__
    for name in hcid.__all__:
        assert getattr(hcid, name) is not None
    with pytest.raises(AttributeError):
        hcid.no_such_name  # noqa: B018


def test_readme_quickstart_runs(capsys, monkeypatch):
    # The README's Python quickstart, executed as written (from the repository root).
    text = (ROOT / "README.md").read_text()
    section = text.split("## Python quickstart", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    monkeypatch.chdir(ROOT)
    namespace: dict = {}
    # It warns that the plant was not checked, as its comment says (the paper's target is no multisine).
    with pytest.warns(UserWarning, match="the plant was not checked"):
        exec(compile(code, "README quickstart", "exec"), namespace)  # noqa: S102
    out = capsys.readouterr().out
    assert "VAF" in out and "Kpt" in out
    # The example is an FF-like subject with Kpt = 0.6 (configs/example_data/make.py).
    assert namespace["model"].nb_ft > 0 and abs(namespace["fit"].values["Kpt"] - 0.6) < 0.1


def test_records_are_the_pipelines(record):
    # read_records = the pipeline's reader with the same names (hcid.io.measured.read_runs).
    from hcid.config import DataConfig
    from hcid.config.parse import default_data
    from hcid.io.measured import read_runs

    data = DataConfig("data", {**default_data().columns, **COLUMNS}, (0.1,))
    runs, rate = read_runs(EXAMPLE, data, 25.0)
    assert rate == record.rate == 25.0 and record.run == 1
    for name in ("t", "ft", "fd", "e", "u"):
        np.testing.assert_array_equal(getattr(record, name), runs[1][name])
    assert record.to_arrow().num_rows == 2048


def test_identification_equals_the_engine_and_selection(record, direct):
    # Source: methods.identify and over_w.select_at, which the CLI's tables are made of.
    found = methods.identify(record.signals, direct.settings, "direct", rate=25.0)
    assert direct.frontier.v.tolist() == found.fit.v.tolist()
    assert direct.frontier.n_rows == 448 and direct.nf == 960
    orders = np.column_stack([found.fit.na, found.fit.nb1, found.fit.nb2, found.fit.nk1, found.fit.nk2])
    for w in (0.0, direct.w_aic, direct.w_bic, 0.1, 0.5):
        model = direct.select(w)
        row = int(over_w.select_at(found.fit.d, found.fit.v, orders, np.array([w]))[0])
        assert model.orders == tuple(int(x) for x in orders[row])
        np.testing.assert_array_equal(model.a, found.fit.a[row])
    path = direct.selection_path()
    assert path.w_from[0] == 0.0 and np.isinf(path.w_to[-1])
    assert path.to_arrow().column("index").to_pylist() == path.index.tolist()


def test_selected_model_response_and_simulation(record, direct):
    # Source: the ARX path formulas of SPEC 5 (path_response) and the engine's simulate on ft_s.
    model = direct.select(direct.w_bic)
    omega = np.logspace(-1, 1.5, 7)
    paths = model.frequency_response(omega)
    np.testing.assert_array_equal(paths["e"], path_response(model.a, model.b_e, model.nk_e, omega, 0.04))
    expected_ft = path_response(model.a, model.b_ft, model.nk_ft, omega, 0.04, advance=1.0)
    np.testing.assert_array_equal(paths["ft"], expected_ft)
    u_hat = model.simulate(record.ft, record.e)
    ft_s = shift_forward(record.ft, 25)
    np.testing.assert_array_equal(
        u_hat, simulate(model.a, model.b_ft, model.b_e, model.nk_ft, model.nk_e, ft_s, record.e)
    )
    assert model.to_arrow().num_rows == 1 and model.to_arrow().column("nb_ft")[0].as_py() == model.nb_ft


def test_api_result_equals_the_cli_tables(tmp_path, ci_config):
    # The same simulated record through the CLI (frontier.parquet) and through hcid.identify.
    from typer.testing import CliRunner

    from hcid.cli import app
    from hcid.io.results import records as read_records_table
    from hcid.tables import SIMULATIONS

    run = tmp_path / "run"
    result = CliRunner().invoke(app, ["identify", str(CI_CONFIG), "--run", str(run), "--quiet", "--jobs", "1",
                                      "--method", "direct"])  # fmt: skip
    assert result.exit_code == 0, result.output
    sims = read_records_table(pq.read_table(run / SIMULATIONS.file), run / SIMULATIONS.file)
    rec = sims[("FF", 1)]
    api = hcid.identify(hcid.Record(1, 25.0, rec["t"], rec["ft"], rec["fd"], rec["e"], rec["u"]), "direct",
                        ci_config.identify)  # fmt: skip
    table = pq.read_table(run / "frontier.parquet")
    keys = zip(table.column("model").to_pylist(), table.column("seed").to_pylist(), strict=True)
    mask = [m == "FF" and s == 1 for m, s in keys]
    cli = table.filter(mask).drop_columns(["model", "seed"])
    assert api.to_arrow().select(cli.column_names).equals(cli)


def test_fit_hc_through_the_api_equals_the_pipelines(record, direct):
    # The same function (hcid.hcfit.selected.fit_selected) as `hcid fit-hc`, with the config's band.
    from hcid.hcfit import parse_fit_settings
    from hcid.hcfit.selected import fit_selected
    from hcid.loop.hcmodel import transfer_function

    model = direct.select(direct.w_bic)
    plant = hcid.Plant.second_order(2.75, 2.0)
    settings = parse_fit_settings({"target": "time", "starts": 1, "maxiter": 8, "popsize": 4},
                                  default_band=(0.23, 17.33))  # fmt: skip
    got = hcid.fit_hc(model, record, hcid.Experiment(plant), settings=settings, plant_check=False)
    want = fit_selected(model, record.signals, transfer_function(plant), settings)
    assert got.estimates == want.estimates and got.names[-3:] == ("Kpt", "TI", "tau_pt")
    assert got.to_arrow().column("parameter").to_pylist() == list(got.names)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda r, d: d.select(-1.0), "w: must be a finite number >= 0"),
        (lambda r, d: hcid.identify({"ft": r.ft}, "direct"), "record: must be a hcid.Record"),
        (lambda r, d: hcid.identify(r, "nope"), "nope"),
        (lambda r, d: hcid.read_records(EXAMPLE, columns={"stick": "u"}), "columns: unknown signal 'stick'"),
        (lambda r, d: hcid.Experiment(hcid.Plant.integrator(1.0), disturbance_at="middle"), "disturbance_at"),
        (
            lambda r, d: hcid.identification_settings(25.0, 2048, {"direct": {"na": [0, 3]}}),
            "identify.direct.na",
        ),
        # A newcomer's notebook (2026-11-27): each refused in one line naming its argument.
        (lambda r, d: hcid.identify(r, "drect"), "method: must be one of direct, indirect, got 'drect'"),
        (lambda r, d: hcid.identify(r, threads=0), "threads: must be an integer >= 1, got 0"),
        (
            lambda r, d: hcid.identify(r, settings={"direct": {}}),
            "settings: must come from hcid.identification",
        ),
        (lambda r, d: hcid.fit_hc(r, d.select(0.1), None), "model: must be a hcid.SelectedModel, got Record"),
        (lambda r, d: hcid.read_records([EXAMPLE]), "path: must be a file's path"),
        (
            lambda r, d: hcid.Record(1, 25.0, r.t[:10], r.ft, r.fd, r.e, r.u),
            r"record t: must be 1-D with the",
        ),
        (
            lambda r, d: hcid.Record(1, 25.0, r.t * 1.1, r.ft, r.fd, r.e, r.u),
            r"record t: step 0.044 s at sample 1, not 1/rate \(0.04 s\)",
        ),
        (
            lambda r, d: hcid.Record(1, 25.0, r.t**1.01, r.ft, r.fd, r.e, r.u),
            "record t: time is not uniformly",
        ),
        (lambda r, d: hcid.Record(1, 25.0, r.t, r.ft + 1j, r.fd, r.e, r.u), "record ft holds complex values"),
        (lambda r, d: hcid.Plant.integrator(float("nan")), "plant.K: must be a finite number > 0, got nan"),
        (lambda r, d: hcid.Plant.tf([1.0], [0.0]), "plant.den: must not be all zero"),
        (lambda r, d: d.selection_path().at(-1.0), "w: must be >= 0, got -1.0"),
        (lambda r, d: hcid.identification_settings(100.0, 4000), "rate: the default identification grids"),
        (lambda r, d: d.select(0.1).frequency_response([1.0, np.nan]), "omega: must be finite .* got nan"),
        (lambda r, d: hcid.Plant.tf(["1"], [1.0, 0.0]), r"plant.num: must be finite numbers, got \['1'\]"),
        (lambda r, d: hcid.Plant.second_order(1.0, 0.0), "plant.wb: must be a finite number > 0, got 0.0"),
        (lambda r, d: hcid.Plant.integrator(-1.5), "plant.K: must be a finite number > 0, got -1.5"),
        (lambda r, d: hcid.analyse(CI_CONFIG, 42, "unused"), r"data: must be files, globs or folders"),
        (
            lambda r, d: hcid.analyse(42, [EXAMPLE], "unused"),
            "config: must be a YAML file's path or the mapping",
        ),
        (lambda r, d: hcid.analyse(CI_CONFIG, [EXAMPLE], 42), "run: must be the run directory's path"),
        (lambda r, d: hcid.Execution(jobs="2"), r"jobs \(--jobs\): must be an integer >= 1, got '2'"),
        (lambda r, d: hcid.AnalysisOptions(twins="4"), "twins \\(--twins\\): must be an integer"),
    ],
)
def test_bad_input_is_one_hcid_error(record, direct, call, message):
    with pytest.raises(hcid.HcidError, match=message):
        call(record, direct)


def test_numpy_integers_are_integers():
    # A notebook's counts often come from numpy (len of an array is int, its .size too, but
    # np.int64 arithmetic is common): accepted where a Python int is.
    assert hcid.identification_settings(25.0, np.int64(1000)) == hcid.identification_settings(25.0, 1000)
    assert hcid.AnalysisOptions(twins=np.int64(4), max_fb_twins=np.int32(8)) == hcid.AnalysisOptions(
        twins=4, max_fb_twins=8
    )


def test_default_settings_are_analyses_for_the_records_rate_and_length(record):
    # Source: SPEC 3 exactly at 25 Hz and 2048 samples (the config parser's sample defaults), and
    # for a shorter record the measured-data defaults `hcid analyse` resolves for a study without an
    # identify section (hcid.config.parse.data_identify_defaults, in seconds).
    from hcid.assembly.resolve import resolve_identify
    from hcid.config import Timing
    from hcid.config.parse import data_identify_defaults

    assert hcid.identification_settings(25.0, 2048) == resolve_identify(None, 25.0, 2048)
    shorter = data_identify_defaults(Timing(25.0, 25.0, 0.0, 40.0, 1))
    assert hcid.identification_settings(25.0, 1000) == resolve_identify(shorter, 25.0, 1000)
    short = hcid.Record(1, 25.0, record.t[:1000], record.ft[:1000], record.fd[:1000], record.e[:1000],
                        record.u[:1000])  # fmt: skip
    direct = hcid.identify(short, "direct").settings.stage("direct")
    assert direct.grid.nk1 == (1, 50) and (direct.estimation.first, direct.validation.last) == (63, 1000)


def test_fit_hc_defaults_to_the_estimator_hcid_analyse_uses(lab_record):
    # Source: a config without a fit section (hcid.hcfit.parse_fit_settings({})) is what
    # `hcid analyse` and `hcid fit-hc` fit with: target auto, the lines estimator on a lab example
    # run (multisines over its 40 s window; configs/lab_example.yaml's columns, rate and lead-in).
    from hcid.hcfit import parse_fit_settings
    from hcid.hcfit.selected import fit_selected
    from hcid.loop.hcmodel import transfer_function

    columns = {"time": "time", "ft": "target", "fd": "disturbance", "e": "error", "u": "stick"}
    path = ROOT / "configs" / "lab_example" / "S1_pursuit_trial1.csv"
    ((run, whole),) = hcid.read_records(path, columns=columns, rate=20.0, lead_in=5.0).items()
    record = hcid.Record(run, 20.0, *(getattr(whole, k)[:800] for k in ("t", "ft", "fd", "e", "u")))
    result = hcid.identify(record, "direct")
    model = result.select(result.w_bic)
    plant = hcid.Plant.integrator(1.5)
    default = hcid.fit_hc(model, record, hcid.Experiment(plant, "input"))
    settings = parse_fit_settings({}, default_band=(2 * np.pi / 40.0, np.pi * 20.0))
    want = fit_selected(model, record.signals, transfer_function(plant), settings, "input")
    assert settings.target == "auto" and default.target == want.target == "lines"
    assert default.estimates == want.estimates
    # Each parameter's status, as analysis.parquet's <name>_status columns hold it (the rules of
    # hcid.hcfit.determined: a fixed parameter, then one on a search bound, say so first).
    import dataclasses

    first = default.names[0]
    assert set(default.status) == set(default.names)
    assert dataclasses.replace(default, fixed=(first,)).status[first] == "fixed at a literature value"
    bounded = dataclasses.replace(default, at_bound=(True, *default.at_bound[1:]))
    assert bounded.status[first] == "at a search bound"


def test_fit_hc_warns_where_it_cannot_check_the_plant(record, direct):
    # The example's target is the paper's, no multisine (hcid.analysis.fourier.forcing_lines finds
    # no lines over its 2048 samples): the plant cannot be checked, and fit_hc says so, once; with
    # plant_check=False it does not.
    import warnings

    from hcid.hcfit import parse_fit_settings

    model = direct.select(direct.w_bic)
    experiment = hcid.Experiment(hcid.Plant.second_order(2.75, 2.0))
    quick = parse_fit_settings({"target": "time", "starts": 1, "maxiter": 4, "popsize": 4},
                               default_band=(0.23, 17.33))  # fmt: skip
    why = "the target is not a sum of sines over whole periods of the window"  # forcing_lines.problem
    with pytest.warns(
        UserWarning, match=rf"^record 1: the plant was not checked over its 2048 samples: {why}"
    ):
        hcid.fit_hc(model, record, experiment, settings=quick)
    with warnings.catch_warnings():
        warnings.filterwarnings("error", "record 1: the plant was not checked", UserWarning)
        hcid.fit_hc(model, record, experiment, settings=quick, plant_check=False)


def test_fit_hc_refuses_a_record_of_another_plant(lab_record):
    # Source: hcid.analysis.fourier.plant_mismatch, which `hcid analyse` refuses a run by: twice
    # the plant's gain leaves theta's every line unexplained by 100% (its doctest).
    result = hcid.identify(lab_record, "direct")
    model = result.select(result.w_bic)
    doubled = hcid.Experiment(hcid.Plant.integrator(3.0), "input")
    with pytest.raises(hcid.DataError, match=r"^record 1: is not the experiment's plant: 100% \(RMS\)"):
        hcid.fit_hc(model, lab_record, doubled)
    assert hcid.fit_hc(model, lab_record, doubled, plant_check=False) is not None


def test_records_and_selections_are_checked(record, direct):
    # Review: a hand-built Record, read_records' rate and select's w are checked at the boundary.
    with pytest.raises(hcid.DataError, match="record u holds nan at sample 3"):
        u = record.u.copy()
        u[3] = np.nan
        hcid.Record(1, 25.0, record.t, record.ft, record.fd, record.e, u)
    with pytest.raises(hcid.DataError, match="record e: must be 1-D with the length of ft"):
        hcid.Record(1, 25.0, record.t, record.ft, record.fd, record.e[:10], record.u)
    for rate in (0, float("nan"), True):
        with pytest.raises(hcid.HcidError, match="rate: must be a positive number"):
            hcid.read_records(EXAMPLE, columns=COLUMNS, rate=rate)
    assert direct.select(np.float32(direct.w_bic)).orders == direct.select(direct.w_bic).orders
    with pytest.raises(hcid.IdentificationError, match="w: must be a finite number"):
        direct.select(True)
