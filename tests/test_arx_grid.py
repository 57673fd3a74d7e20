"""Tests of hcid.arx.grid: candidate enumeration, counts, d (SPEC sections 3, 4)."""

import itertools

import numpy as np
import pytest

from hcid.arx.grid import (
    Grid,
    candidates,
    max_lag,
    n_candidates,
    n_parameters,
    order_blocks,
)
from hcid.errors import ConfigError

# SPEC section 3, grid table.
DIRECT_GRID = Grid(na=(1, 7), nb1=(0, 7), nb2=(0, 7), nk1=(1, 50), nk2=(1, 10))
STAGE1_GRID = Grid(na=(1, 10), nb1=(0, 25), nb2=(0, 10), nk1=(1, 5), nk2=(1, 5))


def _brute_force(grid: Grid) -> set[tuple[int, ...]]:
    """Every (na, nb1, nb2, nk1, nk2) with the nk of a dropped input set to 0."""
    ranges = [range(lo, hi + 1) for lo, hi in (grid.na, grid.nb1, grid.nb2, grid.nk1, grid.nk2)]
    return {
        (na, nb1, nb2, nk1 if nb1 else 0, nk2 if nb2 else 0)
        for na, nb1, nb2, nk1, nk2 in itertools.product(*ranges)
    }


@pytest.mark.parametrize(
    ("grid", "expected"),
    [(DIRECT_GRID, 174_447), (STAGE1_GRID, 64_260)],  # SPEC section 3: "174,447 and 64,260"
)
def test_paper_grid_counts(grid, expected):
    assert n_candidates(grid) == expected
    columns = candidates(grid)
    assert all(c.shape == (expected,) and c.dtype == np.int64 for c in columns)
    assert len(set(zip(*columns, strict=True))) == expected  # no candidate twice


@pytest.mark.parametrize("grid", [DIRECT_GRID, STAGE1_GRID])
def test_dropped_input_is_enumerated_once_with_nk_zero(grid):
    na, nb1, nb2, nk1, nk2 = candidates(grid)
    # SPEC section 3: nb = 0 drops the input and its nk; stored as nk = 0.
    assert np.all(nk1[nb1 == 0] == 0)
    assert np.all(nk2[nb2 == 0] == 0)
    assert np.all(nk1[nb1 > 0] >= grid.nk1[0])
    n_na = grid.na[1] - grid.na[0] + 1
    # Exactly one candidate per na with both inputs dropped.
    assert np.count_nonzero((nb1 == 0) & (nb2 == 0)) == n_na
    # With input 2 dropped: one per (na, nb1 > 0, nk1).
    n_nk1 = grid.nk1[1] - grid.nk1[0] + 1
    assert np.count_nonzero((nb1 > 0) & (nb2 == 0)) == n_na * grid.nb1[1] * n_nk1


def test_candidate_order_is_lexicographic():
    columns = candidates(STAGE1_GRID)
    order = np.lexsort(columns[::-1])
    np.testing.assert_array_equal(order, np.arange(order.size))


@pytest.mark.parametrize(
    "grid",
    [
        Grid(na=(1, 3), nb1=(0, 2), nb2=(0, 3), nk1=(0, 4), nk2=(2, 3)),
        Grid(na=(2, 2), nb1=(1, 3), nb2=(0, 0), nk1=(5, 5), nk2=(1, 9)),
        Grid(na=(1, 4), nb1=(0, 0), nb2=(2, 4), nk1=(1, 3), nk2=(0, 0)),
    ],
)
def test_enumeration_matches_brute_force(grid):
    expected = _brute_force(grid)
    columns = candidates(grid)
    assert set(zip(*(c.tolist() for c in columns), strict=True)) == expected
    assert n_candidates(grid) == len(expected) == columns[0].size


def test_order_blocks_delimit_candidates():
    na, nb1, nb2, start, size = order_blocks(DIRECT_GRID)
    assert na.size == 7 * 8 * 8  # SPEC section 4: "448 rows per realization and method"
    c_na, c_nb1, c_nb2, _, _ = candidates(DIRECT_GRID)
    for row in (0, 1, 8, 100, 447):
        block = slice(start[row], start[row] + size[row])
        assert np.all(c_na[block] == na[row])
        assert np.all(c_nb1[block] == nb1[row])
        assert np.all(c_nb2[block] == nb2[row])
    assert start[-1] + size[-1] == 174_447


def test_n_parameters_formula():
    # SPEC section 4: d = na + nb_ft + nb_e + [nb_ft > 0] + [nb_e > 0].
    assert n_parameters(7, 7, 7) == 23
    assert n_parameters(1, 0, 0) == 1
    assert n_parameters(2, 3, 0) == 6
    assert n_parameters(3, 0, 2) == 6
    na, nb1, nb2, _, _ = candidates(DIRECT_GRID)
    d = n_parameters(na, nb1, nb2)
    np.testing.assert_array_equal(d, na + nb1 + nb2 + (nb1 > 0) + (nb2 > 0))
    assert d.dtype == np.int64


def test_max_lag():
    assert max_lag(STAGE1_GRID) == 29  # SPEC section 3: max(10, 25+5-1, 10+5-1) = 29
    assert max_lag(DIRECT_GRID) == 56  # max(7, 50+7-1, 10+7-1)
    # An input whose nb range is 0..0 contributes no lag.
    assert max_lag(Grid(na=(1, 3), nb1=(0, 0), nb2=(0, 2), nk1=(40, 50), nk2=(1, 1))) == 3


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("na", (0, 3)),  # na must start at 1
        ("nb1", (-1, 3)),
        ("nk2", (-1, 2)),
        ("nb2", (3, 2)),  # lo > hi
        ("nk1", (1.5, 3)),
        ("na", (True, 3)),
        ("nb1", (1, 2, 3)),
        ("nk1", "12"),
        ("nk2", None),
    ],
)
def test_invalid_range_names_the_field(field, value):
    ranges = {"na": (1, 2), "nb1": (0, 2), "nb2": (0, 2), "nk1": (1, 2), "nk2": (1, 2)}
    ranges[field] = value
    with pytest.raises(ConfigError, match=f"Grid.{field}:"):
        Grid(**ranges)


def test_ranges_are_normalised_to_int_tuples():
    grid = Grid(na=[1, np.int64(3)], nb1=(0, 2), nb2=(0, 2), nk1=(1, 2), nk2=(1, 2))
    assert grid.na == (1, 3) and type(grid.na[1]) is int
    assert isinstance(ConfigError("x"), ValueError)
