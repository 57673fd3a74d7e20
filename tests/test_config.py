"""Config loading: the paper values and every kind of bad input."""

import copy

import pytest
import yaml

from hcid.config import load_config, parse_config
from hcid.errors import ConfigError

from .conftest import PAPER_CONFIG


@pytest.fixture(scope="module")
def paper_raw():
    return yaml.safe_load(PAPER_CONFIG.read_text())


def test_paper_config_values(paper_config):
    # SPEC 1 (Table 2), 2 (timing) and 3 (grids, windows).
    assert [m.name for m in paper_config.models] == ["FB", "FF"]
    ff = paper_config.model("FF")
    assert (ff.Kpt, ff.TI, ff.tau_pt, ff.Kpe, ff.TL, ff.tau_pe) == (0.8, 0.25, 0.35, 0.75, 0.4, 0.24)
    assert paper_config.timing.record_samples == 2048
    assert paper_config.seeds == tuple(range(1, 51))
    assert paper_config.identify.stage("direct").estimation.rows() == slice(128, 1088)
    assert paper_config.identify.stage("stage1").estimation.rows() == slice(29, 2048)  # SPEC 3
    assert paper_config.selection.w_grid[0] == pytest.approx(1e-4)
    assert paper_config.selection.w_grid[-1] == pytest.approx(2.0)


def _mutate(raw, path, value):
    data = copy.deepcopy(raw)
    node = data
    *parents, last = path
    for key in parents:
        node = node[key]
    if value is _DELETE:
        del node[last]
    else:
        node[last] = value
    return data


_DELETE = object()

BAD = [
    # (path, value, expected message fragment)
    (("models", "FB", "Kpe_typo"), 1.0, "models.FB.Kpe_typo: unknown key"),
    (("loop", "Kc"), "big", "loop.Kc: must be a number in (0, 1000], got 'big'"),
    (("loop", "remnant_ratio"), 1.5, "loop.remnant_ratio: must be a number in [0, 0.9], got 1.5"),
    (("seeds",), [], "seeds: must be a non-empty list"),
    (
        ("identify", "direct", "na"),
        [0, 3],
        "identify.direct.na: must be an integer range [lo, hi] with 1 <= lo <= hi <= 30, got [0, 3]",
    ),
    (
        ("identify", "direct", "validation"),
        [1089, 4096],
        "identify.direct.validation: must be 'auto' or a sample range",
    ),
    (
        ("identify", "direct", "estimation"),
        [10, 900],
        "identify.direct.estimation: must start after the grid's largest lag",
    ),
    (("timing", "periods"), 0, "timing.periods: must be an integer in [1, 100], got 0"),
    (("signals", "disturbance", "phase"), [0.0, 1.0], "signals.disturbance.phase: must have 20 entries"),
    (("models", "FF", "tau_pt"), 0.355, "models.FF.tau_pt: must be whole samples"),
    (("selection", "w_grid", "min"), -1.0, "selection.w_grid.min: must be a number in (0, 1000], got -1.0"),
    (("loop", "w_n"), _DELETE, "loop.w_n: missing"),
    (("bogus",), 1, "bogus: unknown key"),
]


@pytest.mark.parametrize("path, value, message", BAD, ids=[".".join(b[0]) for b in BAD])
def test_bad_config_names_the_key(paper_raw, path, value, message):
    with pytest.raises(ConfigError) as info:
        parse_config(_mutate(paper_raw, path, value), "paper")
    assert message in str(info.value)
    assert "\n" not in str(info.value)


def test_not_yaml(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("models: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML at line"):
        load_config(bad)


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="cannot read config"):
        load_config(tmp_path / "nope.yaml")


def test_stage2_defaults_to_direct_grid(paper_raw):
    data = copy.deepcopy(paper_raw)
    data["identify"] = {"direct": {"na": [1, 3]}}
    config = parse_config(data, "x")
    assert config.identify.stage("stage2").grid.na == (1, 3)
    assert config.identify.stage("stage2").grid.nk1 == (1, 50)


def test_non_finite_target_step_refused(paper_raw):
    data = _mutate(paper_raw, ("signals", "target", "segments"), [["c", 3, 0], ["p", 3.74, float("inf")]])
    with pytest.raises(
        ConfigError, match=r"signals.target.segments\[1\]: must be \[c\|p, seconds > 0, step\]"
    ):
        parse_config(data, "paper")


def test_target_shift_must_be_whole_samples(paper_raw):
    data = _mutate(paper_raw, ("identify", "target_shift"), 1.01)
    with pytest.raises(ConfigError, match="identify.target_shift: must be whole samples"):
        parse_config(data, "paper")
