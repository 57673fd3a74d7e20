"""Tables on disk: writes checked against the schemas, reads that refuse in one line, atomic writes."""

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from hcid import tables
from hcid.errors import DataError
from hcid.io import results


def _log_row(**overrides):
    row = {"stage": ["simulate"], "seconds": [1.5], "jobs": [2], "finished": ["now"]}
    row.update(overrides)
    return pa.table(row)


def test_write_then_read_round_trip(tmp_path):
    table = pa.Table.from_pydict(
        {"stage": ["simulate"], "seconds": [1.5], "jobs": [2], "finished": ["now"]},
        schema=tables.RUN_LOG.arrow,
    )
    path = results.write(tables.RUN_LOG, table, tmp_path)
    assert path == tmp_path / "run_log.parquet"
    assert results.read(tables.RUN_LOG, tmp_path).equals(table)


def test_write_refuses_a_table_off_its_schema(tmp_path):
    with pytest.raises(AssertionError, match="run_log.parquet: missing columns \\['finished'\\]"):
        results.write(tables.RUN_LOG, _log_row().drop(["finished"]), tmp_path)
    assert not (tmp_path / "run_log.parquet").exists()


@pytest.mark.parametrize(
    ("table", "message"),
    [
        (
            _log_row().drop(["jobs"]),
            "missing columns ['jobs']; written by an older hcid? run the command that wrote it again on "
            "this run directory (it reuses what it can)",
        ),
        (_log_row(seconds=["1.5"]), "column 'seconds' is string, expected double"),
    ],
)
def test_read_names_the_file_and_the_problem(tmp_path, table, message):
    pq.write_table(table, tmp_path / "run_log.parquet")
    with pytest.raises(DataError) as info:
        results.read(tables.RUN_LOG, tmp_path)
    assert str(info.value) == f"{tmp_path / 'run_log.parquet'}: {message}"


def test_read_missing_and_corrupt(tmp_path):
    with pytest.raises(DataError, match="frontier.parquet: missing; run it"):
        results.read(tables.FRONTIER, tmp_path, hint="run it")
    (tmp_path / "frontier.parquet").write_bytes(b"not parquet")
    with pytest.raises(DataError, match="frontier.parquet: not a readable Parquet table"):
        results.read(tables.FRONTIER, tmp_path)
    assert results.read_optional(tables.SELECTION, tmp_path) is None


def test_interrupted_write_leaves_the_previous_table(tmp_path, monkeypatch):
    table = pa.table({"x": np.arange(3)})
    path = tmp_path / "t.parquet"
    results.write_table(table, path)
    before = path.read_bytes()

    def broken(table, where, **options):
        with open(where, "wb") as f:
            f.write(b"half")
        raise OSError("disk full")

    monkeypatch.setattr(pq, "write_table", broken)
    with pytest.raises(DataError, match="cannot write \\(disk full\\); the previous file is intact"):
        results.write_table(pa.table({"x": np.arange(5)}), path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.parquet"]  # no temporary file left


def test_stage_choice_schema_names_its_inputs():
    schema = tables.stage_choice("stage1", ("ft", "fd", "e"))
    assert schema.file == "stage1.parquet"
    assert schema.names[:7] == ("model", "seed", "na", "nb_ft", "nb_fd", "nk_ft", "nk_fd")


def test_thresholds_schema_takes_the_criteria_columns():
    schema = tables.thresholds(["w_aic", "w_mbic"])
    assert "w_mbic" in schema.names and schema.optional[:2] == ("w_aic", "w_mbic")
    # Issue 13's sampling columns and rates at the criteria are optional too: older tables read.
    assert set(tables.UNCERTAINTY_COLUMNS) | {"rate_at_w_aic", "rate_at_w_mbic"} == set(schema.optional[2:])
    row = {"method": "direct", "model": "FB", "has_feedforward": False, "n_realizations": 1}
    row.update(nf=960, w_fp=0.1, w_fn=None)
    old = pa.Table.from_pylist([row], schema=tables.thresholds().arrow)  # no criterion column
    assert tables.thresholds(["w_mbic"]).problem(old) is None  # a table of an older run reads


# --------------------------------------------------------------------------- list naming, parts


def _row(schema: tables.Schema, **values) -> dict:
    """One row of ``schema``: the given values, a placeholder of each other column's type."""
    placeholder = {pa.string(): "x", pa.int64(): 1, pa.float64(): 0.5, pa.bool_(): False}
    return {n: values.get(n, placeholder.get(t, [0.25, -0.5])) for n, t in schema.fields}


def _frontier(model="FB", seed=1, values_named="item") -> pa.Table:
    rows = [_row(tables.FRONTIER, model=model, seed=seed, method="direct", na=na) for na in (1, 2)]
    listed = pa.list_(pa.field(values_named, pa.float64()))
    fields = [(n, listed if isinstance(t, pa.ListType) else t) for n, t in tables.FRONTIER.fields]
    return pa.Table.from_pylist(rows, schema=pa.schema(fields))


def test_a_list_column_writes_the_same_bytes_however_its_values_are_named(tmp_path):
    # Arrow names a list's values "item" when it builds one, Parquet "element"
    # when it reads one back; the types compare equal, but a Parquet file keeps
    # the name. A frontier assembled from tables of both kinds (finished in
    # this run, or read back from an earlier one) must write the same bytes.
    built = _frontier(values_named="item")
    read_back = _frontier(values_named="element")
    assert built.schema.field("a").type == read_back.schema.field("a").type
    paths = [
        results.write(tables.FRONTIER, t, tmp_path / name) for name, t in (("b", built), ("r", read_back))
    ]
    assert paths[0].read_bytes() == paths[1].read_bytes()
    assert pq.read_table(paths[0]).equals(read_back)


def test_read_parts_keeps_whole_parts_of_the_realization_they_name(tmp_path):
    kinds = {"direct": {"frontier": tables.FRONTIER, "log": tables.IDENTIFY_LOG}}

    def log(model, seed):
        return pa.Table.from_pylist(
            [_row(tables.IDENTIFY_LOG, model=model, seed=seed, method="direct")],
            schema=tables.IDENTIFY_LOG.arrow,
        )

    for seed in (1, 2, 3, 4):
        results.write_part(
            tmp_path, "FB", seed, "direct", {"frontier": _frontier(seed=seed), "log": log("FB", seed)}
        )
    folder = tmp_path / results.PARTS / "direct"
    (folder / f"FB__2.log{results.PART_SUFFIX}").unlink()  # one kind missing
    results.write_part_table(
        _frontier(seed=1), folder / f"FB__3.frontier{results.PART_SUFFIX}"
    )  # names seed 1
    path = folder / f"FB__4.frontier{results.PART_SUFFIX}"
    path.write_bytes(path.read_bytes()[:-40])  # cut off mid-write
    found = results.read_parts(tmp_path, kinds)
    assert set(found) == {("FB", 1, "direct")}
    assert found[("FB", 1, "direct")]["frontier"].equals(_frontier(seed=1))


def _simulations(order: np.ndarray) -> pa.Table:
    """Three records of 5 samples (model, seed) = (B, 7), (A, 3), (B, 3), rows taken in ``order``."""
    keys = [("B", 7), ("A", 3), ("B", 3)]
    n = 5
    cols = {
        "model": [m for m, _ in keys for _ in range(n)],
        "seed": [s for _, s in keys for _ in range(n)],
        "k": [k for _ in keys for k in range(n)],
    }
    values = np.arange(len(keys) * n, dtype=float)
    cols.update({name: values * (i + 1) for i, name in enumerate(("t", *tables.CHANNELS))})
    return pa.Table.from_pydict(cols, schema=tables.SIMULATIONS.arrow).take(pa.array(order))


def test_records_split_by_realization_in_order_of_first_appearance():
    # Each record's own rows, in row order, whatever the records' rows are interleaved with.
    contiguous = results.records(_simulations(np.arange(15)), "s.parquet")
    assert list(contiguous) == [("B", 7), ("A", 3), ("B", 3)]
    assert contiguous[("A", 3)]["e"].tolist() == (np.arange(5, 10) * 4.0).tolist()  # t, ft, fd, e: x 4
    interleaved = results.records(_simulations(np.arange(15).reshape(3, 5).T.ravel()), "s.parquet")
    assert list(interleaved) == list(contiguous)
    for key, record in contiguous.items():
        assert all(np.array_equal(record[c], interleaved[key][c]) for c in record)
    with pytest.raises(DataError, match=r"^s.parquet: samples of model A, seed 3 are not k = 0..4 in order$"):
        results.records(_simulations(np.r_[0:5, 6, 5, 7:15]), "s.parquet")


def test_a_table_of_an_older_hcid_names_the_command_that_writes_it(tmp_path):
    # Issue 35: the right next command in every refusal. An analysis table without a column this
    # hcid writes (here the estimator, named `target` before) is refused in one line naming it.
    names = [n for n in tables.ANALYSIS.names if n != "estimator"]
    pq.write_table(
        pa.table({n: pa.nulls(0, t) for n, t in tables.ANALYSIS.fields if n in names}),
        tmp_path / "analysis.parquet",
    )
    with pytest.raises(
        DataError, match=r"missing columns \['estimator'\]; written by an older hcid\? run `hcid analyse"
    ):
        results.read(tables.ANALYSIS, tmp_path)


def _split_by_key_reference(table, keys):
    """The obvious grouping (hcid's before the vectorised one): a dict of row lists, then a take each."""
    cols = [table.column(k).to_pylist() for k in keys]
    groups = {}
    for i, key in enumerate(zip(*cols, strict=True)):
        groups.setdefault(key, []).append(i)
    return {key: table.take(pa.array(rows, pa.int64())) for key, rows in groups.items()}


@pytest.mark.parametrize("chunks", [1, 3])
def test_split_by_key_matches_the_obvious_grouping(chunks):
    # Source: _split_by_key_reference above. Same groups, same first-seen order, same rows in
    # table order, for string, integer, float and null key values over several chunks.
    from hcid.io.results import split_by_key

    rng = np.random.default_rng(5)
    n = 600
    model = rng.choice(["FB", "FF", "x"], n).tolist()
    seed = rng.integers(0, 7, n).tolist()
    w = [
        None if r < 0.05 else float(v)
        for r, v in zip(rng.random(n), rng.choice([0.5, 1.0, 2.0], n), strict=True)
    ]
    table = pa.table({"model": model, "seed": seed, "w": w, "v": rng.random(n)})
    table = pa.concat_tables([table.slice(i * n // chunks, n // chunks) for i in range(chunks)])
    got = split_by_key(table, ("model", "seed", "w"))
    ref = _split_by_key_reference(table, ("model", "seed", "w"))
    assert list(got) == list(ref)
    for key in ref:
        assert got[key].to_pydict() == ref[key].to_pydict()
    assert split_by_key(table.slice(0, 0), ("model",)) == {}


def test_split_by_key_groups_as_dict_keys_do():
    # Source: Python's dict (the obvious grouping): -0.0 and 0.0 are one key, a dictionary
    # column whose dictionary repeats a value groups by value; NaN keys form one group here.
    from hcid.io.results import split_by_key

    t = pa.table({"w": [0.0, -0.0, 0.0, float("nan"), 1.0, float("nan")], "v": [1, 2, 3, 4, 5, 6]})
    got = split_by_key(t, ("w",))
    assert [g.column("v").to_pylist() for g in got.values()] == [[1, 2, 3], [4, 6], [5]]
    d = pa.DictionaryArray.from_arrays(pa.array([0, 1, 0]), pa.array(["a", "a"]))
    assert list(split_by_key(pa.table({"k": d, "v": [1, 2, 3]}), ("k",))) == [("a",)]
    assert split_by_key(t, ()) == {}


def test_a_table_an_earlier_hcid_wrote_is_not_rewritten(tmp_path):
    # Source: results.write's promise (a complete run needs no write and may be read-only): a
    # frontier written with pyarrow's default encoding (hcid before Schema.plain) counts as
    # the same table, so a read-only run directory of an earlier hcid is not written to.
    t = pa.table({"v": [0.5, 0.25], "a": [[1.0, 2.0], [3.0]]})
    path = tmp_path / "t.parquet"
    pq.write_table(t, path)
    assert results._same_table(path, t, ("v",))
    assert not results._same_table(path, pa.table({"v": [0.5, 0.3], "a": [[1.0, 2.0], [3.0]]}), ("v",))


def _realization(model: str, seed: int, n: int, step: int = 1):
    from hcid.loop.simulate import Realization

    rng = np.random.default_rng(seed)
    wide = rng.standard_normal((6, n * step))
    # every other sample of a longer array: views that are not contiguous, as decimation makes
    return Realization(model, seed, np.arange(n) * 0.05, *(wide[i, ::step] for i in range(6)), kn=0.1)


def test_records_of_realizations_equal_their_tables_records():
    # Source: records(realizations_table(r)) is what a written and read simulations.parquet gives.
    made = [_realization("FB", 1, 40, step=2), _realization("FF", 1, 40), _realization("FB", 2, 40, step=3)]
    from_table = results.records(results.realizations_table(made), "simulations.parquet")
    direct = results.records_of(made)
    assert list(direct) == list(from_table) == [("FB", 1), ("FF", 1), ("FB", 2)]
    for key, record in from_table.items():
        assert list(direct[key]) == list(record)
        for name, values in record.items():
            assert direct[key][name].flags.c_contiguous and direct[key][name].dtype == np.float64
            np.testing.assert_array_equal(direct[key][name], values)


def test_records_of_refuses_a_sample_that_is_not_finite():
    bad = _realization("FB", 3, 10)
    bad.u[4] = np.nan
    said = r"simulations.parquet: column 'u' holds nan at model FB, seed 3, k 4"
    with pytest.raises(DataError, match=said):
        results.check_records(results.records_of([bad]), "simulations.parquet")
    with pytest.raises(DataError, match=said):
        results.records(results.realizations_table([bad]), "simulations.parquet")
