"""A plant per level of a data factor (hcid.pipeline.plants; configs/cphs2017.yaml): each run
analysed with its own plant, a plant's runs giving the tables of its own config, and the plant's
effect across people. On the shared CPHS 2017 recordings (skipped where they are absent)."""

import math

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml
from typer.testing import CliRunner

from hcid import tables
from hcid.assembly.resolve import read_study
from hcid.cli import app
from hcid.config import Plant
from hcid.errors import ConfigError, DataError
from hcid.pipeline import Execution, effects
from hcid.pipeline.analyse import AnalysisOptions, analyse_study
from hcid.pipeline.plants import run_plants

from .conftest import ROOT

QUIET = Execution(2, progress=False)
DATA = ROOT.parent / "shared" / "data" / "cphs2017"
BOTH = ROOT / "configs" / "cphs2017.yaml"
SUBJECTS = ("dp", "ef")  # two people: the fewest a comparison across people takes

pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"no recordings at {DATA}")


def _raw() -> dict:
    return yaml.safe_load(BOTH.read_text())


def test_each_run_gets_the_plant_of_its_level():
    # The files' {plant}: fo runs 1/s, so runs 1/(s (s + 1)) (the data's README, "Plants").
    config, data = read_study(BOTH, [str(DATA / "dp_*.csv")])
    plants = run_plants(config, data)
    files = {int(r["run"]): r["file"] for r in data.runs}
    for seed in data.records:
        expected = (1.0, 0.0) if "_fo_" in files[seed] else (1.0, 1.0, 0.0)
        assert plants.plant_of(seed).den == expected
    assert plants.grouping(("subject",)) == ("subject", "plant")  # a group never mixes plants
    assert plants.grouping(("plant", "subject")) == ("plant", "subject")


def test_a_data_set_without_the_factor_is_refused_naming_its_factors():
    raw = _raw()
    raw["data"]["pattern"] = "{subject}_{kind}_r-sos+E_d-sos+O_s49_p0a0_{trial}.csv"
    config, data = read_study(raw, [str(DATA / "dp_*.csv")])
    with pytest.raises(ConfigError) as info:
        run_plants(config, data)
    assert str(info.value) == (
        "loop.plant.by: the data set has no factor 'plant' (its factors: subject, kind, trial; name "
        "them with data.pattern or a manifest)"
    )


def test_a_run_of_a_level_without_a_plant_is_one_line_and_nothing_is_written(tmp_path):
    raw = _raw()
    del raw["loop"]["plant"]["levels"]["so"]
    config_file = tmp_path / "fo_only.yaml"
    config_file.write_text(yaml.safe_dump(raw))
    run = tmp_path / "run"
    found = CliRunner().invoke(
        app, ["analyse", str(config_file), "--data", str(DATA / "dp_*.csv"), "--run", str(run), "--quiet"]
    )
    assert found.exit_code == 2
    assert found.output.strip() == (
        "hcid: error: dp_so_r-sos+E_d-sos+O_s49_p0a0_+1.csv: run 3 has plant 'so', for which "
        "loop.plant.levels gives no plant (it has fo)"
    )
    assert not run.exists()


def test_each_run_is_checked_against_its_own_plant():
    # The so runs against 1/s (both levels the fo plant) are not that plant: refused, naming the level.
    from hcid.pipeline.measured_data import check_plant

    raw = _raw()
    raw["loop"]["plant"]["levels"]["so"] = raw["loop"]["plant"]["levels"]["fo"]
    config, data = read_study(raw, [str(DATA / "dp_*.csv")])
    with pytest.raises(DataError, match=r"is not the configured plant: .* loop.plant.levels.so 1/s with"):
        check_plant(config, data)
    check_plant(*read_study(BOTH, [str(DATA / "dp_*.csv")]))  # each its own: accepted


def test_the_model_inversion_at_the_lines_uses_each_runs_own_plant():
    # |Ht Yc| (dB) = |Ht| (dB) + 20 log10 |Yc(j w)| exactly, Yc the run's own plant; with one plant
    # the quantity is left out (it would repeat |Ht|'s effects).
    config, data = read_study(BOTH, [str(DATA / "dp_*.csv")])
    plants = run_plants(config, data)
    rate, n = config.timing.output_rate, config.timing.record_samples
    own = {s: plants.plant_of(s) for s in data.records}
    with_yc = effects.line_values(data.records, rate, n, own)
    assert effects.line_values(data.records, rate, n) == {
        s: [v for v in values if not v[0].startswith("|Ht Yc|")] for s, values in with_yc.items()
    }
    for seed, values in with_yc.items():
        named = dict(values)
        inversion = [q for q in named if q.startswith("|Ht Yc| at ")]
        assert len(inversion) == (6 if own[seed].den == (1.0, 0.0) else 4)  # the README's target lines
        for q in inversion:
            w = float(q.split(" at ")[1].split(" rad/s")[0])
            omega = next(x for x in _target_lines(data.records[seed], rate, n) if f"{x:.3g}" == f"{w:.3g}")
            yc_db = 20 * np.log10(abs(own[seed].response(np.array([omega]))[0]))
            assert named[q] == pytest.approx(named[f"|Ht| at {q.split(' at ')[1]}"] + yc_db, abs=1e-9)


def _target_lines(record, rate, n):
    from hcid.analysis.fourier import fc_estimate

    return fc_estimate([record], rate, slice(0, n)).omega_t


def test_line_effects_are_those_of_the_lines_every_level_has():
    # so's lines are some of fo's (the README: target k = 2, 5, 11, 17 of fo's 2, ..., 31): a line
    # of fo only has no contrast and is left out, not refused.
    rows, lines = [], {}
    for i, (subject, plant) in enumerate([(s, p) for s in "abc" for p in ("fo", "so")]):
        rows.append({"run_id": i, "method": "direct", "subject": subject, "plant": plant})
        lines[i] = [("|Ht| at 1 rad/s", 1.0 + i + (plant == "so"))] + (
            [("|Ht| at 9 rad/s", 2.0)] if plant == "fo" else []
        )
    found = effects.effects_rows([{**r, **_blank_fit()} for r in rows], "plant", "subject", lines)
    free = [e for e in found if e["source"] == effects.MODEL_FREE]
    assert {e["quantity"] for e in free} == {"|Ht| at 1 rad/s"}
    mixed = next(e for e in free if e["test"] == "mixed model (REML)")
    assert mixed["estimate"] == pytest.approx(2.0)  # so - fo: (i + 1 + 1) - i per subject, exactly


def _blank_fit() -> dict:
    out = {name: math.nan for name, _ in effects.LOOP_FIGURES}
    for p in tables.HC_PARAMETER_NAMES:
        out.update({p: math.nan, f"{p}_se": math.nan, f"{p}_status": "not fitted"})
    return out


@pytest.fixture(scope="module")
def studies(tmp_path_factory):
    """Subjects dp and ef: both plants in one study (--by plant --compare plant), and each plant
    with its own config (--by plant), two twins each and no more FB twins (about 35 s)."""
    root = tmp_path_factory.mktemp("plants")
    options = AnalysisOptions(by="plant", twins=2, max_fb_twins=2)
    config, data = read_study(BOTH, [str(DATA / f"{s}_*.csv") for s in SUBJECTS])
    both = analyse_study(
        config,
        root / "both",
        data,
        AnalysisOptions(**{**options.__dict__, "compare": "plant"}),
        execution=QUIET,
    )
    apart = {}
    for plant in ("fo", "so"):
        files = [str(DATA / f"{s}_{plant}_*.csv") for s in SUBJECTS]
        config, data = read_study(ROOT / "configs" / f"cphs2017_{plant}.yaml", files)
        apart[plant] = analyse_study(config, root / plant, data, options, execution=QUIET)
    return both, apart


def test_each_plants_runs_give_the_tables_of_its_own_config(studies):
    # Every per-run column (p-values, W*, W, parameters, loop figures, data checks) and every group
    # column of the combined study equal the plant's own study's (the same groups, twins and
    # seeds); only the run ids (numbered over each data set) and the data set's name differ.
    both, apart = studies
    mine = {(r["file"], r["method"]): r for r in both.runs.to_pylist()}
    for plant, alone in apart.items():
        for row in alone.runs.to_pylist():
            combined = mine[(row["file"], row["method"])]
            assert combined["plant"] == plant
            for key, value in row.items():
                if key not in ("run_id", "data_set"):
                    assert _same(combined[key], value), (plant, row["file"], key)
        groups = {(g["group"], g["method"]): g for g in both.groups.to_pylist()}
        for row in alone.groups.to_pylist():
            assert all(_same(groups[(row["group"], row["method"])][k], v) for k, v in row.items())
    for name in (tables.FC_ESTIMATES.file, tables.EVIDENCE_TWINS.file):
        combined = pq.read_table(both.run_dir / name).to_pylist()
        alone = [r for plant in ("fo", "so") for r in pq.read_table(apart[plant].run_dir / name).to_pylist()]
        assert sorted(map(repr, combined)) == sorted(map(repr, alone)), name


def _same(a, b) -> bool:
    return (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)) or a == b


def test_the_plant_effect_is_compared_at_every_shared_line(studies):
    both, _ = studies
    rows = pq.read_table(both.run_dir / tables.STUDY_EFFECTS.file).to_pylist()
    assert {r["effect"] for r in rows} == {"plant: so - fo"}
    quantities = {(r["source"], r["quantity"]) for r in rows}
    for method in ("direct", "indirect"):
        assert {(method, q) for q in ("Kpt", "tau_pt", "crossover")} <= quantities
    # The lines both plants have (the README: so's target k = 2, 5, 11, 17 and disturbance
    # k = 3, 7, 13 of 20 s; fo's further lines have no so runs): |Ht| and |Ht Yc| at each target line.
    for path, ks in (("|Ht|", (2, 5, 11, 17)), ("|Ht Yc|", (2, 5, 11, 17)), ("|He|", (3, 7, 13))):
        at = sorted(round(float(q.split(" at ")[1].split()[0]) * 20 / (2 * math.pi)) for s, q in quantities
                    if s == effects.MODEL_FREE and q.startswith(path + " at "))  # fmt: skip
        assert at == list(ks), path
    # Each run's |Ht Yc| is its |Ht| times its own plant: per subject so's minus fo's is |Ht|'s
    # plus 20 log10 |Yc_so / Yc_fo| = -10 log10(1 + w^2) dB, so the mixed model's estimates differ
    # by exactly that (both weight every run alike: no se).
    mixed = {
        r["quantity"]: r
        for r in rows
        if r["source"] == effects.MODEL_FREE and r["test"] == "mixed model (REML)"
    }
    for q, r in mixed.items():
        if q.startswith("|Ht Yc| at "):
            w = 2 * math.pi * round(float(q.split(" at ")[1].split()[0]) * 20 / (2 * math.pi)) / 20
            ht = mixed[q.replace("|Ht Yc|", "|Ht|")]
            # A balanced design (2 runs per subject and plant): the estimate is the difference of
            # means whatever the variances, so the shift is exact.
            assert r["estimate"] - ht["estimate"] == pytest.approx(-10 * np.log10(1 + w**2), abs=1e-6)
            assert r["subjects"] == 2 and r["runs"] == 8


def test_plant_response_is_yc_at_j_omega():
    # Yc = 1/(s (s + 1)) at s = 2j: 1 / (2j (2j + 1)) = 1 / (-4 + 2j).
    assert Plant.tf([1.0], [1.0, 1.0, 0.0]).response(np.array([2.0]))[0] == pytest.approx(1 / (-4 + 2j))
