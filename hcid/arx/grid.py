"""Candidate grids of MISO ARX models (SPEC sections 3 and 4).

A candidate is the model

    A(q) o(k) = B1(q) i1(k - nk1) + B2(q) i2(k - nk2) + eps(k)

with ``A = 1 + a1 q^-1 + ... + a_na q^-na`` and ``B = b_0 + ... + b_{nb-1}
q^-(nb-1)``. A grid gives each of the five integers an inclusive range. An
input with ``nb = 0`` is dropped; its delay is then meaningless, so such a
candidate is enumerated once and stores ``nk = 0`` for the dropped input.

The candidate order, used everywhere a per-candidate array appears, is
lexicographic in ``(na, nb1, nb2, nk1, nk2)`` with the stored ``nk = 0`` of a
dropped input: all candidates of one order triple ``(na, nb1, nb2)`` form one
contiguous block, the blocks follow each other in lexicographic order of the
triple, and inside a block ``nk1`` varies slowest.
"""

from __future__ import annotations

import numpy as np

from hcid.config.types import Grid

__all__ = [
    "Grid",
    "candidates",
    "max_lag",
    "n_candidates",
    "n_parameters",
    "order_blocks",
]


def n_parameters(na, nb1, nb2):
    """Number of parameters ``d`` of a candidate (SPEC section 4).

    ``d = na + nb1 + nb2 + [nb1 > 0] + [nb2 > 0]``: each delay of a used
    input counts as one parameter.

    Parameters
    ----------
    na, nb1, nb2 : int or array_like of int
        Orders; arrays broadcast.

    Returns
    -------
    int or numpy.ndarray of int64
        ``d``, an int for scalar input, else an int64 array of the broadcast
        shape.
    """
    na, nb1, nb2 = np.asarray(na), np.asarray(nb1), np.asarray(nb2)
    d = (na + nb1 + nb2 + (nb1 > 0) + (nb2 > 0)).astype(np.int64)
    return int(d) if d.ndim == 0 else d


def max_lag(grid: Grid) -> int:
    """Largest lag, in samples, that any candidate of ``grid`` uses (:attr:`Grid.max_lag`)."""
    return grid.max_lag


def _delay_count(nb: int, nk: tuple[int, int]) -> int:
    return nk[1] - nk[0] + 1 if nb > 0 else 1


def order_blocks(grid: Grid) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Order triples of ``grid`` and where their candidate blocks start.

    Parameters
    ----------
    grid : Grid

    Returns
    -------
    na, nb1, nb2 : numpy.ndarray of int64, shape (n_blocks,)
        The order triples in lexicographic order.
    start : numpy.ndarray of int64, shape (n_blocks,)
        Index of each block's first candidate in the order of
        :func:`candidates`.
    size : numpy.ndarray of int64, shape (n_blocks,)
        Number of candidates (delay combinations) of each block.
    """
    na, nb1, nb2 = np.meshgrid(
        np.arange(grid.na[0], grid.na[1] + 1),
        np.arange(grid.nb1[0], grid.nb1[1] + 1),
        np.arange(grid.nb2[0], grid.nb2[1] + 1),
        indexing="ij",
    )
    na, nb1, nb2 = (x.ravel().astype(np.int64) for x in (na, nb1, nb2))
    n1 = np.where(nb1 > 0, grid.nk1[1] - grid.nk1[0] + 1, 1)
    n2 = np.where(nb2 > 0, grid.nk2[1] - grid.nk2[0] + 1, 1)
    size = (n1 * n2).astype(np.int64)
    start = np.concatenate(([0], np.cumsum(size)[:-1])).astype(np.int64)
    return na, nb1, nb2, start, size


def n_candidates(grid: Grid) -> int:
    """Number of distinct candidates of ``grid``.

    Parameters
    ----------
    grid : Grid

    Returns
    -------
    int
        174,447 for the paper's direct / stage-2 grid and 64,260 for its
        stage-1 grid (SPEC section 3).
    """
    per_na = sum(
        _delay_count(nb1, grid.nk1) * _delay_count(nb2, grid.nk2)
        for nb1 in range(grid.nb1[0], grid.nb1[1] + 1)
        for nb2 in range(grid.nb2[0], grid.nb2[1] + 1)
    )
    return per_na * (grid.na[1] - grid.na[0] + 1)


def candidates(grid: Grid) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every candidate of ``grid``, once, in the module's candidate order.

    Parameters
    ----------
    grid : Grid

    Returns
    -------
    na, nb1, nb2, nk1, nk2 : numpy.ndarray of int64, shape (n_candidates,)
        Lexicographic in ``(na, nb1, nb2, nk1, nk2)``; a dropped input
        (``nb = 0``) has ``nk = 0``.
    """
    block_na, block_nb1, block_nb2, start, size = order_blocks(grid)
    na = np.repeat(block_na, size)
    nb1 = np.repeat(block_nb1, size)
    nb2 = np.repeat(block_nb2, size)
    # Position inside the block, nk1 slowest; a dropped input has one "delay".
    within = np.arange(size.sum(), dtype=np.int64) - np.repeat(start, size)
    n_delays2 = np.where(nb2 > 0, grid.nk2[1] - grid.nk2[0] + 1, 1)
    nk1 = np.where(nb1 > 0, grid.nk1[0] + within // n_delays2, 0)
    nk2 = np.where(nb2 > 0, grid.nk2[0] + within % n_delays2, 0)
    return na, nb1, nb2, nk1.astype(np.int64), nk2.astype(np.int64)
