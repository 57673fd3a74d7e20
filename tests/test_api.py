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
    assert direct.frontier.column("v").to_numpy().tolist() == found.fit.v.tolist()
    assert direct.frontier.num_rows == 448 and direct.nf == 960
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
    assert api.frontier.select(cli.column_names).equals(cli)


def test_fit_hc_through_the_api_equals_the_pipelines(record, direct):
    # The same function (hcid.analysis.selected.fit_selected) as `hcid fit-hc`, with the config's band.
    from hcid.analysis.selected import fit_selected
    from hcid.hcfit import parse_fit_settings
    from hcid.loop.hcmodel import transfer_function

    model = direct.select(direct.w_bic)
    plant = hcid.Plant.second_order(2.75, 2.0)
    settings = parse_fit_settings({"target": "time", "starts": 1, "maxiter": 8, "popsize": 4},
                                  default_band=(0.23, 17.33))  # fmt: skip
    got = hcid.fit_hc(model, record, hcid.Experiment(plant), settings=settings)
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
    ],
)
def test_bad_input_is_one_hcid_error(record, direct, call, message):
    with pytest.raises(hcid.HcidError, match=message):
        call(record, direct)


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
