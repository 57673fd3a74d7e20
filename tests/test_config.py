"""Config loading: the paper values and every kind of bad input."""

import copy

import numpy as np
import pytest
import yaml

from hcid.assembly.resolve import load_config, parse_config
from hcid.errors import ConfigError

from .conftest import PAPER_CONFIG, ROOT


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
    assert paper_config.noise_stream == 0  # no stream: each seed's own noise (white_noise)
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
    (("seeds",), {"first": 1, "count": 2, "stream": -1}, "seeds.stream: must be an integer in [0, "),
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
    (("models", "FF", "tau_pt"), -2.5, "models.FF.tau_pt: must be a number in [-2, 2], got -2.5"),
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
        ConfigError, match=r"signals.target.segments\[1\]: must be \[c\|p\|r, seconds > 0, step\]"
    ):
        parse_config(data, "paper")


def test_target_shift_must_be_whole_samples(paper_raw):
    data = _mutate(paper_raw, ("identify", "target_shift"), 1.01)
    with pytest.raises(ConfigError, match="identify.target_shift: must be whole samples"):
        parse_config(data, "paper")


# --------------------------------------------------------------------------- hostile input (issue 10)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            'a0: &a0 ["lol", "lol", "lol"]\na1: &a1 [*a0, *a0, *a0]\n',
            "line 2: YAML aliases (*name) are not allowed in a config",
        ),
        ("x: " + "[" * 20000 + "]" * 20000 + "\n", "line 1: nested deeper than 40 levels"),
        ("seeds: [" + "9" * 5000 + "]\n", "not a usable config ('Exceeds the limit (4300 digits)"),
        ("name: a\nname: b\n", "line 2: duplicate key 'name'"),
    ],
)
def test_hostile_yaml_is_one_line(tmp_path, text, message):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value).startswith(f"{path}: {message}")
    assert len(str(info.value)) < 300 and "\n" not in str(info.value)


def test_non_utf8_and_oversized_files(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_bytes(b"name: \xff\n")
    with pytest.raises(ConfigError, match="not UTF-8 text \\(byte 0xff at offset 6\\)"):
        load_config(path)
    path.write_text("# " + "x" * (1 << 20))
    with pytest.raises(ConfigError, match="larger than 1,048,576 bytes"):
        load_config(path)


def test_unstable_closed_loop_is_refused(paper_raw):
    # Kc = 99 makes the FB loop unstable: |z| of the largest pole of 1 + Yc He z^-24 = 0 is 1.06.
    data = _mutate(paper_raw, ("loop", "Kc"), 99)
    with pytest.raises(
        ConfigError, match=r"models.FB: the closed loop with this plant is unstable \(pole at z = "
    ):
        parse_config(data, "paper")


def test_stability_check_agrees_with_simulation(paper_config):
    # The parse-time check against a simulation: at Kc = 8 the largest closed-loop pole has
    # |z| = 1.0056 and the noise-free loop grows without bound; at Kc = 5 (|z| = 0.9945) it does not.
    import dataclasses

    import numpy as np

    from hcid.config import Plant
    from hcid.loop.hcmodel import DiscreteLoop, closed_loop_poles
    from hcid.loop.simulate import simulate_loop

    fb = paper_config.model("FB")
    for kc, grows in ((5.0, False), (8.0, True)):
        loop = dataclasses.replace(paper_config.loop, plant=Plant.second_order(kc, 2.0))
        assert (np.max(np.abs(closed_loop_poles(fb, loop, 0.01))) >= 1) == grows
        n = 20000
        fd = np.zeros(n)
        fd[0] = 1e-3
        out = simulate_loop(DiscreteLoop.build(fb, loop, 0.01), np.zeros(n), fd, np.zeros(n))
        late, early = np.max(np.abs(out["e"][-2000:])), np.max(np.abs(out["e"][:2000]))
        assert (late > 10 * early) == grows


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        (
            ("identify", "direct"),
            None,
            "identify.direct: must be a mapping (leave the key out for the defaults)",
        ),
        (
            ("identify", "direct", "validation"),
            [2048, 2048],
            "identify.direct.validation: must hold at least",
        ),
        (("seeds",), list(range(10_001)), "seeds: must hold at most 10,000 seeds"),
        (("name",), "..", "name: must be 1 to 100 letters"),
        (("name",), "a\0b", "name: must be 1 to 100 letters"),
        (("timing", "periods"), 100, "timing: a simulation of"),
    ],
)
def test_values_that_cannot_work_are_refused(paper_raw, path, value, message):
    data = _mutate(paper_raw, path, value)
    if path == ("timing", "periods"):
        data["timing"]["sim_rate"] = 10000.0
    with pytest.raises(ConfigError) as info:
        parse_config(data, "paper")
    assert str(info.value).startswith(message)


def test_grid_of_billions_of_candidates_is_refused(paper_raw):
    grid = {"na": [1, 30], "nb1": [0, 60], "nb2": [0, 60], "nk1": [0, 200], "nk2": [0, 200]}
    data = _mutate(paper_raw, ("identify", "direct"), {**grid, "estimation": [300, 1088]})
    with pytest.raises(ConfigError, match="identify.direct: the grid has 4,364,031,630 candidates, at most"):
        parse_config(data, "paper")


def test_error_messages_quote_at_most_80_characters(paper_raw):
    data = _mutate(paper_raw, ("loop", "Kc"), "x" * 10_000)
    with pytest.raises(ConfigError) as info:
        parse_config(data, "paper")
    assert len(str(info.value)) < 160


# --------------------------------------------------------------------------- plants (SPEC 7)


def _with_plant(raw, plant, **loop_keys):
    data = copy.deepcopy(raw)
    del data["loop"]["Kc"], data["loop"]["wb"]
    data["loop"]["plant"] = plant
    data["loop"].update(loop_keys)
    return data


@pytest.mark.parametrize(
    ("plant", "num", "den"),
    [
        ({"kind": "integrator", "K": 1.5}, (1.5,), (1.0, 0.0)),
        ({"kind": "double_integrator", "K": 0.5}, (0.5,), (1.0, 0.0, 0.0)),
        ({"kind": "second_order", "K": 2.75, "wb": 2.0}, (5.5,), (1.0, 2.0, 0.0)),
        ({"kind": "tf", "num": [0, 0, 5.5], "den": [1, 2, 0]}, (5.5,), (1.0, 2.0, 0.0)),
    ],
)
def test_plant_shorthands(paper_raw, plant, num, den):
    # K/s, K/s^2, K wb/(s (s + wb)) and a tf with leading zeros stripped.
    config = parse_config(_with_plant(paper_raw, plant), "x")
    assert (config.loop.plant.num, config.loop.plant.den) == (num, den)
    assert config.loop.disturbance_at == "output"


def test_paper_plant_is_the_default(paper_config):
    # No loop.plant: the paper's Kc wb / (s (s + wb)) with Kc = 2.75, wb = 2, bit for bit.
    # Loop holds the plant itself: no Kc/wb fields that read 0.0 for another plant (issue 25).
    import dataclasses

    assert paper_config.loop.plant.kind == "second_order"
    assert not {"Kc", "wb"} & {f.name for f in dataclasses.fields(paper_config.loop)}
    assert (paper_config.loop.plant.num, paper_config.loop.plant.den) == ((2.75 * 2.0,), (1.0, 2.0, 0.0))


@pytest.mark.parametrize(
    ("plant", "extra", "message"),
    [
        ({"kind": "cubic"}, {}, "loop.plant.kind: unknown plant shorthand 'cubic' (allowed: second_order, "),
        ({"kind": "tf", "num": [1, 0, 0], "den": [1, 1]}, {}, "loop.plant: must be proper"),
        # Each rule of hcid.config.types.check_plant, and the config's own: den from its leading power.
        ({"kind": "tf", "num": [1, 2, 3], "den": [0, 1, 0]}, {}, "loop.plant.den: the leading coefficient"),
        ({"kind": "tf", "num": [0, 0], "den": [1, 1]}, {}, "loop.plant.num: must not be all zero"),
        ({"kind": "tf", "num": [1], "den": [0, 0]}, {}, "loop.plant.den: must not be all zero"),
        (
            {"kind": "tf", "num": [1], "den": [1] * 12},
            {},
            "loop.plant.den: must hold at most 11 coefficients",
        ),
        ({"kind": "integrator", "K": 1}, {"disturbance_at": "middle"}, "loop.disturbance_at: must be one of"),
        # Yc = (1 - s) / (s (s + 1)): its zero at s = 1 is a pole of the Inverse Feedforward Model.
        (
            {"kind": "tf", "num": [-1, 1], "den": [1, 1, 0]},
            {},
            "models.FF: the feedforward path Ynms Kpt / Yc / (TI s + 1)^2 is unstable",
        ),
    ],
)
def test_bad_plants(paper_raw, plant, extra, message):
    with pytest.raises(ConfigError) as info:
        parse_config(_with_plant(paper_raw, plant, **extra), "x")
    assert message in str(info.value)
    assert "\n" not in str(info.value)


def test_plant_given_twice_is_refused(paper_raw):
    data = copy.deepcopy(paper_raw)
    data["loop"]["plant"] = {"kind": "integrator", "K": 1}
    with pytest.raises(ConfigError, match="loop.Kc: give the plant either as loop.Kc and loop.wb"):
        parse_config(data, "x")


# --------------------------------------------------------------------------- forcing functions (SPEC 7)


def test_forcing_function_kinds(paper_raw, tmp_path):
    # A multisine target, a segments disturbance (with a ramp) and a file column, each parsed
    # into its own type; a file path is read relative to the config's folder.
    from hcid.config import FileSignal, Multisine, Segments

    data = copy.deepcopy(paper_raw)
    data["signals"]["target"] = {
        "kind": "multisine",
        "base_period": 81.92,
        "k": [2, 5],
        "amplitude": [0.1, 0.2],
        "phase": [0, 1],
    }
    data["signals"]["disturbance"] = {
        "kind": "segments",
        "gain_deg": 1.0,
        "segments": [["c", 2, 0], ["r", 3, 1]],
    }
    config = parse_config(data, "x")
    assert isinstance(config.target, Multisine) and config.target.time_offset == 0.0
    assert isinstance(config.disturbance, Segments) and config.disturbance.segments[1].kind == "r"
    (tmp_path / "sig.csv").write_text("t,fd\n" + "".join(f"{i / 25},{0.01 * (i % 7)}\n" for i in range(2048)))
    data["signals"]["disturbance"] = {"kind": "file", "path": "sig.csv", "column": "fd", "rate": 25.0}
    config = parse_config(data, "x", tmp_path)
    assert isinstance(config.disturbance, FileSignal) and config.disturbance.values.size == 2048


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        (
            {"kind": "chirp"},
            "signals.disturbance.kind: unknown forcing function 'chirp' (allowed: multisine, ",
        ),
        ({"kind": "file", "path": "sig.csv", "column": "nope", "rate": 25.0}, "signals.disturbance: "),
        ({"kind": "file", "path": "absent.csv", "column": "fd", "rate": 25.0}, "absent.csv: missing"),
        ({"kind": "file", "path": "sig.csv", "column": "fd", "rate": 25.0, "start": 10.0}, "needs 2298"),
        (
            {"kind": "file", "path": "sig.csv", "column": "fd", "rate": 25.0, "start": 0.01},
            "must be whole samples",
        ),
    ],
)
def test_bad_forcing_functions(paper_raw, tmp_path, spec, message):
    (tmp_path / "sig.csv").write_text("t,fd\n" + "".join(f"{i / 25},0.01\n" for i in range(2048)))
    data = copy.deepcopy(paper_raw)
    data["signals"]["disturbance"] = spec
    with pytest.raises(ConfigError) as info:
        parse_config(data, "x", tmp_path)
    assert message in str(info.value) and "\n" not in str(info.value)
    if spec.get("column") == "nope":
        assert str(info.value).endswith("has no column 'nope'")


# --------------------------------------------------------------------------- windows in seconds (issue 11)


def test_windows_in_seconds_equal_the_paper_samples(paper_raw, paper_config):
    # SPEC 3 at 25 Hz: samples 129..1088 are [5.12 s, 43.52 s), 1089..2048 are [43.52 s, 81.92 s).
    data = copy.deepcopy(paper_raw)
    data["identify"]["windows_in"] = "seconds"
    for stage in ("direct", "stage2"):
        data["identify"][stage].update(estimation=[5.12, 43.52], validation=[43.52, 81.92])
    config = parse_config(data, "paper")
    assert config.identify == paper_config.identify
    assert config.to_yaml() == paper_config.to_yaml()  # the resolved config holds samples


def test_stage2_inherits_seconds_from_direct(paper_raw, paper_config):
    data = copy.deepcopy(paper_raw)
    data["identify"]["windows_in"] = "seconds"
    data["identify"]["direct"].update(estimation=[5.12, 43.52], validation=[43.52, 81.92])
    del data["identify"]["stage2"]
    assert parse_config(data, "paper").identify == paper_config.identify


@pytest.mark.parametrize(
    ("window", "message"),
    [
        (
            [5.13, 43.52],
            "identify.direct.estimation: 5.13 s is not a whole number of samples at the analysis rate 25 Hz",
        ),
        ([5.12, 90.0], "identify.direct.estimation: must end within the record (81.92 s, 2048 samples)"),
        ([43.52, 5.12], "identify.direct.estimation: must be 'auto' or [start, end] in s"),
    ],
)
def test_bad_windows_in_seconds(paper_raw, window, message):
    data = copy.deepcopy(paper_raw)
    data["identify"]["windows_in"] = "seconds"
    data["identify"]["direct"]["estimation"] = window
    data["identify"]["direct"]["validation"] = [43.52, 81.92]
    with pytest.raises(ConfigError) as info:
        parse_config(data, "paper")
    assert message in str(info.value) and "\n" not in str(info.value)


def test_a_default_window_beyond_a_short_record_is_named_as_the_methods_default():
    # Issue 48: the lab example (40 s at 20 Hz: 800 samples) with an identify section that gives
    # one stage's window only: the direct method's default, SPEC 3's samples 129..1088, was
    # refused as though the user had given it ("must be ... <= 800, got [129, 1088]").
    from hcid.assembly.resolve import read_study

    raw = yaml.safe_load((ROOT / "configs" / "lab_example.yaml").read_text())
    raw["identify"] = {"stage1": {"estimation": [4, 42.5]}}
    with pytest.raises(ConfigError) as info:
        read_study(raw, [str(ROOT / "configs" / "lab_example" / "S1_pursuit_trial1.csv")])
    assert str(info.value) == (
        "identify.direct.estimation: the method's default window [129, 1088] (samples) does not fit "
        "this record of 800 samples (40 s); give identify.direct.estimation (in seconds with "
        "identify.windows_in: seconds), or leave the identify section out for windows scaled to the record"
    )


# ---------------------------------------------------------------------- no silent wrong answers (issue 24)


def _file_disturbance(raw, tmp_path, values, **spec):
    (tmp_path / "fd.csv").write_text("fd\n" + "".join(f"{float(v)!r}\n" for v in values))
    data = copy.deepcopy(raw)
    data["signals"]["disturbance"] = {"kind": "file", "path": "fd.csv", "column": "fd", "rate": 25.0, **spec}
    return data


def test_a_forcing_files_run_needs_its_run_column(paper_raw, tmp_path):
    # Before: run 2 of a file without a run column simulated with the whole column, exit 0.
    data = _file_disturbance(paper_raw, tmp_path, np.sin(np.arange(2048) / 3.0), run=2)
    with pytest.raises(ConfigError, match="run 2 asked for, but the file has no run column 'run'"):
        parse_config(data, "x", tmp_path)


@pytest.mark.parametrize("peak", [1e150, 1e101])
def test_forcing_file_values_have_the_data_bound(paper_raw, tmp_path, peak):
    # Before: accepted, then "every one of the 1300 candidates is unstable" at identify.
    values = np.sin(np.arange(2048) / 3.0) * peak
    with pytest.raises(
        ConfigError, match=r"signals.disturbance: .*column 'fd' holds .* at sample \d+ \(values"
    ):
        parse_config(_file_disturbance(paper_raw, tmp_path, values), "x", tmp_path)


@pytest.mark.parametrize(
    ("name", "edit", "how"),
    [
        ("disturbance", lambda s: s["disturbance"].update(amplitude=[0.0] * 20), "every amplitude is 0"),
        ("target", lambda s: s["target"].update(gain_deg=0.0), "its gain or every step is 0"),
    ],
)
def test_a_constant_forcing_function_is_refused(paper_raw, name, edit, how):
    # Before: Kn = 0, var(n)/var(u) NaN, every seed identical, the remnant ratio ignored.
    data = copy.deepcopy(paper_raw)
    edit(data["signals"])
    with pytest.raises(ConfigError, match=f"signals.{name}: is constant over the window \\({how}\\); "):
        parse_config(data, "x")


def test_a_file_disturbance_of_zeros_is_refused(paper_raw, tmp_path):
    with pytest.raises(ConfigError, match=r"column 'fd' is constant \(0\)\); the remnant gain"):
        parse_config(_file_disturbance(paper_raw, tmp_path, np.zeros(2048)), "x", tmp_path)


def test_fit_hc_band_above_nyquist_is_refused(paper_raw):
    # The analysis rate is 25 Hz: Nyquist pi x 25 = 78.54 rad/s.
    data = copy.deepcopy(paper_raw)
    data["fit_hc"] = {"band": [0.1, 80.0]}
    with pytest.raises(
        ConfigError, match=r"fit_hc.band: must end at or below the analysis Nyquist .*78.54 rad/s"
    ):
        parse_config(data, "x")
    data["fit_hc"] = {"band": [0.1, 78.5]}
    assert parse_config(data, "x").fit_hc.band == (0.1, 78.5)


def test_improper_plant_message_quotes_at_most_80_characters(paper_raw):
    # Before: 230 characters of the plant quoted; errors.QUOTE is the documented limit.
    # Yc = 1 / (s^6 + ...): relative degree 6, so Ynms Kpt / Yc / (TI s + 1)^2 is improper.
    plant = {"kind": "tf", "num": [1.0], "den": [1.0, 2.3456789, 3.456789, 4.567891, 5.678912, 6.789123, 0.0]}
    with pytest.raises(ConfigError) as info:
        parse_config(_with_plant(paper_raw, plant), "x")
    text = str(info.value)
    assert "is improper for the plant '(1) / (1 s^6 + 2.34568 s^5" in text
    quoted = text.split("for the plant ")[1].split(" (relative degree")[0]
    assert len(quoted) == 80 and quoted.endswith("...")


def test_a_measured_study_names_its_optional_sections_among_the_allowed_keys():
    # A data-only config that misspells loop: the refusal lists loop and timing, which it may hold.
    raw = {"name": "x", "data": {"analysis_rate": 25.0, "window": 40.0}, "loops": {}}
    with pytest.raises(
        ConfigError, match=r"^loops: unknown key \(allowed: data, fit_hc, identify, loop, name, "
    ):
        parse_config(raw, "x")


def test_a_measured_study_with_both_timings_is_told_which_to_keep():
    # data.analysis_rate and a timing section give the analysis rate twice: the refusal says so
    # (it had asked for timing.sim_rate, a simulation's key, as if timing were meant whole).
    raw = {"name": "x", "data": {"analysis_rate": 25.0, "window": 40.0}, "timing": {"output_rate": 25.0}}
    with pytest.raises(ConfigError, match=r"^timing: a measured study's timing is data.analysis_rate and "):
        parse_config(raw, "x")
    raw["data"] = {"window": 40.0}  # either of data's two timing keys
    with pytest.raises(ConfigError, match=r"^timing: a measured study's timing is data.analysis_rate and "):
        parse_config(raw, "x")


def test_a_window_in_seconds_given_as_samples_is_told_the_unit_key():
    # 40 s at 20 Hz: 800 samples; [0.2, 21.24] are seconds, not samples: the refusal names
    # identify.windows_in. Whole numbers stay samples and get no hint.
    window = {"estimation": [0.2, 21.24], "validation": [21.24, 40.0]}
    raw = {"name": "x", "data": {"analysis_rate": 20.0, "window": 40.0}, "identify": {"direct": window}}
    with pytest.raises(ConfigError, match=r"\(1-based, inclusive\); in seconds \(40 s of record\) with "
                       r"identify.windows_in: seconds, got \[0.2, 21.24\]$"):  # fmt: skip
        parse_config(raw, "x")
    raw["identify"]["direct"] = {"estimation": [0, 400], "validation": [401, 800]}
    with pytest.raises(ConfigError, match=r"\(1-based, inclusive\), got \[0, 400\]$"):
        parse_config(raw, "x")


# --------------------------------------------------------------------------- a plant per level


@pytest.fixture()
def both_plants_raw():
    return yaml.safe_load((PAPER_CONFIG.parent / "cphs2017.yaml").read_text())


def test_a_plant_per_level_is_parsed_into_each_levels_plant(both_plants_raw):
    # configs/cphs2017.yaml: fo 1/s and so 1/(s (s + 1)), the plants of cphs2017_fo.yaml and
    # cphs2017_so.yaml; a level's config is the one-plant config of that plant.
    from hcid.config import PlantByFactor

    config = parse_config(both_plants_raw, "x")
    assert isinstance(config.loop.plant, PlantByFactor) and config.plant_factor == "plant"
    assert [(n, p.num, p.den) for n, p in config.loop.plant.levels] == [
        ("fo", (1.0,), (1.0, 0.0)),
        ("so", (1.0,), (1.0, 1.0, 0.0)),
    ]
    for level in ("fo", "so"):
        own = load_config(PAPER_CONFIG.parent / f"cphs2017_{level}.yaml")
        mine = config.with_plant(level)
        assert mine.loop == own.loop and mine.plant_factor is None
        assert mine.raw["loop"] == own.raw["loop"]  # the twins' configs copy it
    with pytest.raises(
        ConfigError, match=r"^loop.plant.levels: gives no plant for plant 'xo' \(it has fo, so\)$"
    ):
        config.with_plant("xo")


@pytest.mark.parametrize(
    ("plant", "message"),
    [
        (
            {
                "by": "plant",
                "levels": {
                    "fo": {"kind": "integrator", "K": 1.0},
                    "so": {"kind": "second_order", "K": 1.0, "wb": -1},
                },
            },
            "loop.plant.levels.so.wb: must be a number in (0, 10000], got -1.0",
        ),
        (
            {"by": "plant", "levels": {"fo": {"kind": "integrator", "K": 1.0, "wb": 2.0}}},
            "loop.plant.levels.fo.wb: unknown key (allowed: K, kind)",
        ),
        (
            {"by": "plant", "levels": {"fo": {"kind": "cubic"}}},
            "loop.plant.levels.fo.kind: unknown plant shorthand 'cubic' (allowed: second_order, integrator, "
            "double_integrator, tf)",
        ),
        (
            {"by": "plant", "levels": {"so": {"kind": "tf", "num": [1.0], "den": [0.0, 1.0, 0.0]}}},
            "loop.plant.levels.so.den: the leading coefficient must not be 0, got [0.0, 1.0, 0.0]",
        ),
        (
            {"by": "plant", "levels": {"so": {"kind": "tf", "num": [1.0, 0.0, 0.0], "den": [1.0, 1.0]}}},
            "loop.plant.levels.so: must be proper (degree of num <= degree of den), got degrees 2 and 1",
        ),
        (
            {"by": "plant", "kind": "integrator", "levels": {"fo": {"kind": "integrator", "K": 1.0}}},
            "loop.plant.kind: unknown key (allowed: by, levels)",
        ),
        (
            {"by": "run", "levels": {"fo": {"kind": "integrator", "K": 1.0}}},
            "loop.plant.by: must be a data factor's name (an identifier other than model, seed, run, file, "
            "file_run, method, w, k, t), got 'run'",
        ),
        ({"by": "plant"}, "loop.plant.levels: missing"),
        (
            {"by": "plant", "levels": {}},
            "loop.plant.levels: must be a non-empty mapping of each level of 'plant' to its plant, got {}",
        ),
        (
            {"by": "session", "levels": {1: {"kind": "integrator", "K": 1.0}}},
            "loop.plant.levels: each level must be a factor value as text (quote a number: '1'), got 1",
        ),
    ],
)
def test_a_bad_plant_per_level_names_its_dotted_key(both_plants_raw, plant, message):
    data = copy.deepcopy(both_plants_raw)
    data["loop"]["plant"] = plant
    with pytest.raises(ConfigError) as info:
        parse_config(data, "x")
    assert str(info.value) == message


def test_a_config_that_simulates_refuses_a_plant_per_level(paper_raw):
    # hcid simulate / run / calibrate-w of the paper study simulate one plant.
    plant = {"by": "plant", "levels": {"fo": {"kind": "integrator", "K": 1.0}}}
    with pytest.raises(ConfigError) as info:
        parse_config(_with_plant(paper_raw, plant), "x")
    assert str(info.value) == (
        "loop.plant.by: a plant per level of a data factor is for a measured study (hcid analyse); a "
        "config that simulates (models, signals, seeds) needs one plant"
    )


def test_fit_hc_refuses_a_plant_per_level_in_one_line(tmp_path):
    from typer.testing import CliRunner

    from hcid.cli import app

    (tmp_path / "run").mkdir()  # a run directory to fit in (as hcid analyse leaves one)
    found = CliRunner().invoke(
        app, ["fit-hc", str(PAPER_CONFIG.parent / "cphs2017.yaml"), "--run", str(tmp_path / "run")]
    )
    assert found.exit_code == 2
    assert found.output.strip() == (
        "hcid: error: loop.plant.by: `hcid fit-hc` needs one plant; this config gives one per level of "
        "'plant' (fo, so): give each plant a config of its own"
    )
    assert not any((tmp_path / "run").iterdir())  # nothing written


def test_a_noise_stream_is_read_from_seeds(paper_raw):
    # Source: the config reference (docs/configuration.md, seeds): {first, count, stream}.
    config = parse_config({**paper_raw, "seeds": {"first": 1, "count": 2, "stream": 99}}, "paper")
    assert config.seeds == (1, 2) and config.noise_stream == 99
