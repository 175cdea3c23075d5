"""The gate's rules on cells and nodes (the one home of each; :mod:`ffdcli.quality.gate` states them
in words and counts them, the polyhedral gate reuses them).
"""

from __future__ import annotations

import numpy as np

from ffdcli.mesh.idsets import unique_ids
from ffdcli.quality.metrics import raw_quality
from ffdcli.quality.orthogonality import node_orthogonality

#: Default threshold of the scaled Jacobian below which a cell that got worse fails the gate.
DEFAULT_THRESHOLD = 0.05
#: A cell below the threshold fails only if its quality dropped below this fraction of before.
DEFAULT_RELATIVE = 0.5
#: ... and only if it also falls below this (or below the input mesh's worst cell, if lower).
DEFAULT_COLLAPSE = 0.01
#: A node fails when its orthogonality (degrees) falls below this ...
DEFAULT_ORTHO_MIN = 20.0
#: ... after losing more than this many degrees from the input mesh.
DEFAULT_ORTHO_LOSS = 10.0
#: A failing cell is the design's own (not refused) when its quality is at least this fraction of
#: what the design's FFD map itself makes of it ...
DESIGN_SLACK = 0.9
#: ... and a failing node when its orthogonality is at most this many degrees below the map's.
DESIGN_SLACK_DEG = 2.0


def collapse_floor(min_valid_before: float | None, collapse: float) -> float:
    """The quality under which a cell made worse fails: the lower of ``collapse`` and the input
    mesh's worst valid cell (0 when the input has no valid cell)."""
    return min(0.0 if min_valid_before is None else float(min_valid_before), collapse)


def cell_rule(q: np.ndarray, qb: np.ndarray | None, threshold: float, relative: float, floor: float | None):
    """The gate's rule on cells (the one home, see the module docstring), for any set of cells.

    ``q``, ``qb``: (k,) scaled Jacobians after and before (``qb`` None: no mesh before); ``floor``:
    :func:`collapse_floor` of the WHOLE input mesh. Returns the (k,) masks ``(inverted, below,
    bad_in, new_inv, worse, failed)`` (the three of the before None without one)."""
    inverted = q <= 0
    below = ~inverted & (q < threshold)
    if qb is None:
        return inverted, below, None, None, None, inverted
    bad_in = qb <= 0
    valid = ~bad_in
    new_inv = inverted & valid
    worse = valid & ~inverted & (q < threshold) & (q < relative * qb) & (q < floor)
    return inverted, below, bad_in, new_inv, worse, new_inv | worse


def node_rule(o: np.ndarray, o_ref: np.ndarray, has: np.ndarray, ortho_min: float, ortho_loss: float):
    """The gate's rule on nodes (the one home): ``(loss, fail)`` of orthogonality after ``o`` and
    before ``o_ref`` (degrees), where ``has`` (nodes of some cell)."""
    loss = np.where(has, o_ref - o, 0.0)
    return loss, has & (o < ortho_min) & (loss > ortho_loss)


def shaped_by_design(after, cells, index, q, design_map, orientation) -> np.ndarray:
    """The rule *shaped by the design* on cells (the one home): the cells of ``index`` (numbered in
    the concatenation of ``cells``) whose quality ``q`` is at least ``DESIGN_SLACK`` x what the
    design's own map (``design_map``, see :func:`check_quality`) makes of them, every node mapped."""
    starts = np.cumsum([0] + [len(b) for b in cells])
    blk = np.searchsorted(starts, index, side="right") - 1
    per_block = [cells[k].data[index[blk == k] - starts[k]] for k in range(len(cells))]
    nodes = unique_ids(*per_block)
    moved = np.asarray(design_map(nodes), dtype=np.float64)
    good = np.isfinite(moved).all(axis=1)
    pts = np.array(after, dtype=np.float64)
    pts[nodes[good]] = moved[good]
    mapped = np.zeros(len(pts), dtype=bool)
    mapped[nodes[good]] = True
    q_map = np.full(len(index), np.inf)
    for k, data in enumerate(per_block):
        if len(data):
            raw = raw_quality(pts, data, cells[k].type, orientation.normal)
            q_map[blk == k] = np.where(mapped[data].all(axis=1),
                                       np.clip(orientation.signs[k] * raw, -1.0, 1.0), np.inf)
    return index[q[index] >= DESIGN_SLACK * q_map]


def nodes_shaped_by_design(after, cells, dim, orientation, topology, fail, o, design_map) -> np.ndarray:
    """The rule *shaped by the design* on nodes (the one home): the failing nodes (mask ``fail``)
    whose orthogonality ``o`` is at most ``DESIGN_SLACK_DEG`` below what it is when the nodes of
    their cells move by the design's own map (the node itself mapped)."""
    cand = np.flatnonzero(fail)
    near = np.zeros(len(after), dtype=bool)
    near[cand] = True
    around = [b.data[near[b.data].any(axis=1)] for b in cells]
    nodes = unique_ids(*around)
    moved = np.asarray(design_map(nodes), dtype=np.float64)
    good = np.isfinite(moved).all(axis=1)
    pts = np.array(after, dtype=np.float64)
    pts[nodes[good]] = moved[good]
    o_map = node_orthogonality(pts, cells, dim, orientation=orientation, topology=topology)
    mapped = np.zeros(len(pts), dtype=bool)
    mapped[nodes[good]] = True
    return cand[mapped[cand] & (o[cand] >= o_map[cand] - DESIGN_SLACK_DEG)]
