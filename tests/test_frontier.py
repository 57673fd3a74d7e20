"""The frontier in memory (hcid.selection.frontier.Frontier) against the table it is read from."""

import numpy as np
import pyarrow as pa
import pytest

from hcid import tables
from hcid.io import results
from hcid.selection import over_w
from hcid.selection.frontier import Frontier

# Source: a hand-made frontier of two records (model, seed, method), three order triples each;
# the second record's coefficients follow the first's in the list columns' child arrays.
ROWS = [
    # model, seed, method, na, nb_ft, nb_e, nk_ft, nk_e, d, v, a, b_ft, b_e
    ("FB", 1, "direct", 1, 0, 1, 0, 2, 3, 0.5, [1.0, -0.5], [], [0.25]),
    ("FB", 1, "direct", 1, 1, 1, 3, 2, 5, 0.4, [1.0, -0.4], [0.1], [0.2]),
    ("FB", 1, "direct", 2, 1, 1, 3, 2, 6, np.inf, [], [], []),
    ("FF", 2, "direct", 1, 0, 1, 0, 1, 3, 0.9, [1.0, -0.7], [], [0.3]),
    ("FF", 2, "direct", 1, 2, 1, 2, 1, 6, 0.3, [1.0, -0.6], [0.2, 0.1], [0.4]),
    ("FF", 2, "direct", 2, 2, 1, 2, 1, 7, 0.29, [1.0, -0.6, 0.1], [0.2, 0.05], [0.4]),
]


def _table() -> pa.Table:
    names = ["model", "seed", "method", "na", "nb_ft", "nb_e", "nk_ft", "nk_e", "d", "v", "a", "b_ft", "b_e"]
    columns = {n: [r[i] for r in ROWS] for i, n in enumerate(names)}
    columns["vaf_estimation"] = [90.0 - i for i in range(len(ROWS))]
    columns["vaf_validation"] = [80.0 - i for i in range(len(ROWS))]
    columns["n_unstable"] = [0, 0, 4, 0, 1, 0]
    return pa.Table.from_pydict(columns, schema=tables.FRONTIER.arrow)


def test_split_frontiers_keep_each_records_rows_and_coefficients():
    table = _table()
    got = results.frontiers(table)
    assert list(got) == [("FB", 1, "direct"), ("FF", 2, "direct")]
    ff = got[("FF", 2, "direct")]
    assert ff.method == "direct" and ff.n_rows == 3
    assert ff.nb_ft.tolist() == [0, 2, 2] and ff.v.tolist() == [0.9, 0.3, 0.29]
    # the second record's slice of the list columns, not the child array's start
    np.testing.assert_array_equal(ff.row_coefficients(2)["a"], [1.0, -0.6, 0.1])
    np.testing.assert_array_equal(ff.row_coefficients(1)["b_ft"], [0.2, 0.1])
    assert ff.row_coefficients(0)["b_ft"].size == 0
    # back to the table's columns, bit for bit
    mine = table.slice(3, 3).drop_columns(["model", "seed"])
    assert ff.to_arrow().equals(mine)


def test_selection_is_breakpoints_of_the_rows():
    fb = results.frontiers(_table())[("FB", 1, "direct")]
    path = fb.path()
    ref = over_w.breakpoints(np.array([3, 5, 6]), np.array([0.5, 0.4, np.inf]), fb.orders)
    np.testing.assert_array_equal(path.index, ref.index)
    np.testing.assert_array_equal(path.w_from, ref.w_from)
    # exact switch: log 0.5 + 3 W = log 0.4 + 5 W at W = log(0.5 / 0.4) / 2
    w_switch = np.log(0.5 / 0.4) / 2
    assert path.w_from[1] == pytest.approx(w_switch, rel=1e-15)
    assert fb.select([0.0, w_switch * 0.99, w_switch * 1.01]).tolist() == [1, 1, 0]


def test_one_record_only():
    one = _table().slice(0, 3)
    with pytest.raises(ValueError, match="got method"):
        Frontier.from_table(one.set_column(2, "method", pa.array(["direct", "direct", "indirect"])))
    with pytest.raises(ValueError, match="got model"):
        Frontier.from_table(_table())  # two records of one method


def test_a_rows_coefficients_are_its_own():
    ff = results.frontiers(_table())[("FF", 2, "direct")]
    mine = ff.row_coefficients(1)
    mine["a"][1] = 99.0
    assert ff.row_coefficients(1)["a"].tolist() == [1.0, -0.6]


def test_chunked_columns():
    # Source: the same rows in three record batches (as concatenated parts are) read as one table.
    table = _table()
    chunked = pa.Table.from_batches(table.to_batches(max_chunksize=2))
    assert chunked.column("a").num_chunks == 3
    for key, one in results.frontiers(chunked).items():
        ref = results.frontiers(table)[key]
        assert one.to_arrow().equals(ref.to_arrow())
        for row in range(one.n_rows):
            for c, v in one.row_coefficients(row).items():
                np.testing.assert_array_equal(v, ref.row_coefficients(row)[c])
