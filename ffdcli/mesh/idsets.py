"""Sorted sets of integer ids (node ids, cell ids, ranks): unique, union, difference.

NumPy >= 2.3 gives ``np.unique`` (and ``np.union1d``, ``np.setdiff1d`` without ``assume_unique``,
which call it) a hash table for integer arrays. On this project's machines that route is 10-30x
slower than sorting: 4M random ids below 1M take 3.6 s in ``np.unique`` against 0.12 s sorted
(NumPy 2.4.6, 2026-12-02), and the reading by parts, the warp's roles and the quality gate take
unions of that size (the read of a 1M-node SU2 mesh at 2 ranks spent 2.9 of its 6.6 s in it).
These functions sort instead
(results equal to NumPy's: sorted, each id once) and are what the package uses for id sets;
``np.unique`` stays for floats and for calls with ``return_index``/``return_inverse``/``axis``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["unique_ids", "union_ids", "setdiff_ids"]


def unique_ids(*arrays) -> np.ndarray:
    """The sorted distinct values of the integer ``arrays`` (any shapes, flattened and joined).

    Parameters
    ----------
    *arrays : array_like of int
        One or more arrays; none, or only empty ones, give an empty int64 array.

    Returns
    -------
    ndarray of int, shape (M,)
        Sorted, each value once (``np.unique(np.concatenate([a.ravel() for a in arrays]))``).
    """
    parts = [np.asarray(a).ravel() for a in arrays]
    flat = np.concatenate(parts) if parts else np.zeros(0, np.int64)
    if flat.size == 0:
        return flat.astype(np.int64) if flat.dtype.kind not in "iu" else flat
    flat.sort()                      # in place: np.concatenate made a new array (inputs never reordered)
    keep = np.empty(flat.shape, dtype=bool)
    keep[0] = True
    np.not_equal(flat[1:], flat[:-1], out=keep[1:])
    return flat[keep]


def union_ids(a, b) -> np.ndarray:
    """Sorted union of two integer arrays (``np.union1d``)."""
    return unique_ids(a, b)


def setdiff_ids(a, b) -> np.ndarray:
    """Sorted distinct values of ``a`` that are not in ``b`` (``np.setdiff1d``)."""
    a = unique_ids(a)
    b = np.asarray(b).ravel()
    return a[~np.isin(a, b)] if b.size else a
