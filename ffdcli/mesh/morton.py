"""The Z-order (Morton) curve of a point set: one curve for the warp's targets and the mesh partition.

Points close in space get close codes, so sorting by code puts neighbours together in memory
(the warp's targets walk the same tree nodes) and cutting the sorted order into runs gives
compact pieces of a mesh (:mod:`ffdcli.parallel.partition`).
"""

from __future__ import annotations

import numpy as np


def morton_order(pos: np.ndarray) -> np.ndarray:
    """Permutation sorting points along a Z-order curve (21 bits per axis) of their bounding box."""
    if len(pos) == 0:
        return np.zeros(0, dtype=np.int64)
    lo = pos.min(axis=0)
    ext = np.maximum(pos.max(axis=0) - lo, 1e-300)
    return np.argsort(morton_codes(pos, lo, ext), kind="stable")


def morton_codes(pos: np.ndarray, lo: np.ndarray, ext) -> np.ndarray:
    """(n,) uint64 Z-order codes of ``pos`` (n, 3) in the box ``lo + [0, ext]`` (``lo`` (3,), ``ext``
    (3,) or a number, > 0): 21 bits per axis, x in the lowest bit. Points of the box only (a point
    below ``lo`` has no code); a code depends on the point and the box alone, so ranks holding
    different points of one box compute the codes a single process would."""
    q = np.minimum(((pos - lo) / ext * (2 ** 21 - 1)).astype(np.uint64), 2 ** 21 - 1)
    code = np.zeros(len(pos), dtype=np.uint64)
    for k in range(3):
        code |= _spread_bits(q[:, k]) << np.uint64(k)
    return code


def _spread_bits(v: np.ndarray) -> np.ndarray:
    v = v & np.uint64(0x1FFFFF)
    v = (v | (v << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
    v = (v | (v << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
    v = (v | (v << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
    v = (v | (v << np.uint64(2))) & np.uint64(0x1249249249249249)
    return v
