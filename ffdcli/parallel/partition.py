"""One rank's share of a mesh: the nodes it owns (a compact piece of space), the cells around them and their halo.

An MPI run (:mod:`ffdcli.parallel.comm`) gives every node an owner rank (:func:`block_owners`, and
:func:`node_owners` for a whole mesh: the same rule): the nodes sorted along a Z-order (Morton)
curve of their coordinates, cut into ``size`` runs of equal length, so that a rank owns a compact
piece of space whatever the file's numbering (contiguous blocks of ids would give every rank cells
all over a mesh numbered by a mesher's entities). The cuts are found from each rank's block of
rows (a distributed selection), so no rank needs every node's coordinates to know its own nodes. What a
rank needs of the volume mesh to judge its nodes and cells (the quality gate) is a :class:`MeshPart`:

* the cells that touch an owned node, in global order within each cell block (so every edge of an
  owned node has all its cells here: its dual face, and so the node's orthogonality, is computed
  by the same additions in the same order as in the serial run);
* the coordinates of every node of those cells (owned nodes and the halo), local ids sorted by
  global id (the renumbering keeps the order of ids, so sorts and tie-breaks agree with serial);
* the global index of each local cell, and which cells this rank counts: a cell is counted by the
  rank that owns its first node (exactly one rank).

Parts are built from a whole mesh (:func:`part_of`, the rank that holds it) or read directly by
rank (:func:`ffdcli.io.formats.cgns.read_part`, :func:`ffdcli.io.formats.su2.read_part`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ffdcli.mesh import CELL_NODES, CellBlock, Mesh
from ffdcli.mesh.idsets import union_ids, unique_ids
from ffdcli.mesh.morton import morton_codes  # the one Z-order curve (the warp orders its targets by it)
from ffdcli.parallel.comm import SerialComm, share


@dataclass(frozen=True, eq=False)
class MeshPart:
    """One rank's share of a mesh's volume (see the module docstring).

    n_points, n_cells
        Global node and cell counts.
    rank
        The rank whose part this is.
    ids
        (n,) sorted global ids of the local nodes (owned and halo).
    points
        (n, 3) their coordinates.
    owned
        (n,) bool: the local nodes this rank owns.
    dim
        Topological dimension of the cells.
    types
        Cell type of every global cell block, in the mesh's order (the same on every rank, empty
        blocks included: the gate's orientation is per block).
    cells
        One :class:`CellBlock` per entry of ``types``, node ids LOCAL (rows of ``points``).
    cell_ids
        Per block: (k,) global index of each local cell in the concatenation of the mesh's blocks.
    counted
        Per block: (k,) bool, the cells this rank counts (it owns their first node).
    rows
        (n,) the rows of ``ids`` in this rank's local mesh (:func:`localize`); ``None`` when the part
        was taken from a mesh that has every node (then rows are ``ids``).
    """

    n_points: int
    n_cells: int
    rank: int
    ids: np.ndarray
    points: np.ndarray
    owned: np.ndarray
    dim: int
    types: tuple
    cells: tuple
    cell_ids: tuple
    counted: tuple
    rows: np.ndarray | None = None

    def take(self, points: np.ndarray) -> np.ndarray:
        """The part's rows of an (N, 3) array of every node, or of the rank's local mesh's rows
        when the part belongs to a local mesh (``rows`` set)."""
        return np.asarray(points, dtype=np.float64)[self.ids if self.rows is None else self.rows]

    def nbytes(self) -> int:
        """Bytes held by the part's arrays (points, ids, cells)."""
        return int(self.ids.nbytes + self.points.nbytes + self.owned.nbytes + sum(b.data.nbytes for b in self.cells)
                   + sum(c.nbytes for c in self.cell_ids) + sum(c.nbytes for c in self.counted))


#: Bits of the Morton code (63) and then of the global id that each round of the distributed
#: selection of :func:`block_owners` decides: one histogram of 2^15 bins over all points, then
#: 2^12 bins per cut over the points still in the running.
FIRST_BITS, NEXT_BITS = 15, 12


def node_owners(points: np.ndarray, size: int) -> np.ndarray:
    """(N,) int32 owner rank of every node of a whole mesh: :func:`block_owners` with every node in
    one block (the same rule, so a mesh read whole and one read by parts have the same owners)."""
    return block_owners(SerialComm(), points, 0, len(points), size)


def block_owners(comm, points: np.ndarray, start: int, n: int, size: int | None = None) -> np.ndarray:
    """(m,) int32 owner rank of the nodes ``start .. start + m - 1`` (``points`` (m, 3)) of a mesh of
    ``n`` nodes whose rows are spread over the ranks of ``comm`` in blocks; a collective.

    The rule: the nodes sorted along a Z-order (Morton) curve of the mesh's bounding cube
    (:func:`ffdcli.mesh.morton.morton_codes`; ties, the nodes of one code, by global id), cut into
    ``size`` (default ``comm.size``) runs of equal length (:func:`ffdcli.parallel.comm.share`): exactly
    those of a sort of every node, but found without any rank holding every node. The cube is
    all-gathered (two corners a rank); the ``size - 1`` cut keys are found by a distributed radix
    selection (:data:`FIRST_BITS`, :data:`NEXT_BITS`): each round, the ranks' histograms of the next
    bits of the nodes still in the running are summed (``allreduce_sum``, exact below 2^53 nodes),
    which fixes those bits of every cut; at most 5 rounds of the code and 1-3 of the id (a cut
    that no other node shares a code with is fixed by then too: the rounds run to the end anyway).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    size = comm.size if size is None else int(size)
    owner = np.zeros(len(pts), dtype=np.int32)
    if size == 1 or n == 0:
        return owner
    # the same scale on every axis: a thin mesh (one cell thick, a planar 2D mesh) is cut across its
    # plane, not through its thickness
    box = [b for b in comm.allgather((pts.min(axis=0), pts.max(axis=0)) if len(pts) else None) if b is not None]
    lo = np.min([b[0] for b in box], axis=0)
    ext = max(float(np.max(np.max([b[1] for b in box], axis=0) - lo)), 1e-300)
    code = morton_codes(pts, lo, ext)
    gid = np.arange(start, start + len(pts), dtype=np.uint64)
    cut_code, cut_gid = _select(comm, code, gid, n, size)
    # owner = how many cut keys (code, id) are <= the node's: the cuts of smaller codes, then ties
    low = np.searchsorted(cut_code, code, side="left")
    high = np.searchsorted(cut_code, code, side="right")
    owner[:] = low
    tie = np.flatnonzero(high > low)
    for j in range(int((high - low).max(initial=0))):       # at most size - 1 cuts share one code
        at = low[tie] + j
        inside = at < high[tie]
        owner[tie] += inside & (cut_gid[np.minimum(at, len(cut_gid) - 1)] <= gid[tie])
    return owner


def _select(comm, code: np.ndarray, gid: np.ndarray, n: int, size: int) -> tuple[np.ndarray, np.ndarray]:
    """The keys (code, global id) of the nodes at sorted positions ``share(n, r, size)[0]``,
    r = 1 .. size - 1 (nondecreasing), by rounds of summed histograms (see :func:`block_owners`)."""
    targets = np.array([share(n, r, size)[0] for r in range(1, size)], dtype=np.int64)
    digits = ([(0, s, b) for s, b in _digits(63, FIRST_BITS)]
              + [(1, s, b) for s, b in _digits(max(1, (n - 1).bit_length()), NEXT_BITS)])
    keys = (code, gid)
    prefix = np.zeros((len(targets), 2), dtype=np.uint64)
    below = np.zeros(len(targets), dtype=np.int64)      # nodes of a smaller key than the cut's prefix
    groups = [np.arange(len(code))]                      # per distinct prefix: the local nodes in the running
    member = np.zeros(len(targets), dtype=np.int64)      # each cut's group
    for word, shift, bits in digits:
        nb = 1 << bits
        digit = [((keys[word][c] >> np.uint64(shift)) & np.uint64(nb - 1)).astype(np.int64) for c in groups]
        hist = np.zeros((len(groups), nb))
        for g, d in enumerate(digit):
            hist[g] = np.bincount(d, minlength=nb)
        cum = np.cumsum(comm.allreduce_sum(hist), axis=1).astype(np.int64)
        chosen = np.empty(len(targets), dtype=np.int64)
        for t in range(len(targets)):                    # a loop over the cuts (ranks), not nodes
            row = cum[member[t]]
            d = int(np.searchsorted(row, targets[t] - below[t], side="right"))
            below[t] += row[d - 1] if d else 0
            prefix[t, word] |= np.uint64(d) << np.uint64(shift)
            chosen[t] = d
        pairs, member = np.unique(np.stack([member, chosen], axis=1), axis=0, return_inverse=True)
        member = member.ravel()
        groups = [groups[g][digit[g] == d] for g, d in pairs.tolist()]
    return prefix[:, 0], prefix[:, 1]


def _digits(bits: int, width: int) -> list[tuple[int, int]]:
    """(shift, width) of the digits of a ``bits``-bit key, most significant first (the first
    ``width`` wide, the others :data:`NEXT_BITS`)."""
    out, top = [], bits
    while top > 0:
        w = min(width, top)
        out.append((top - w, w))
        top -= w
        width = NEXT_BITS
    return out


def touching(data: np.ndarray, owner: np.ndarray, rank: int) -> np.ndarray:
    """(k,) bool: the cells (rows of ``data``, global node ids) with a node that ``rank`` owns."""
    if not len(data):
        return np.zeros(0, dtype=bool)
    return np.any(owner[data] == rank, axis=1)


def assemble_part(n_points: int, n_cells: int, owner: np.ndarray, rank: int, dim: int, types, blocks,
                  cell_ids, coordinates) -> MeshPart:
    """A :class:`MeshPart` from the cells touching the nodes ``rank`` owns (global node ids).

    Parameters
    ----------
    owner
        (N,) owner rank of every node (:func:`node_owners`).
    blocks
        Per entry of ``types``: (k, nodes) global node ids of the cells touching the owned nodes,
        in global order.
    cell_ids
        Per block: (k,) their global cell indices.
    coordinates
        ``coordinates(ids) -> (len(ids), 3)``: the coordinates of sorted global node ids.
    """
    blocks = [np.asarray(b, dtype=np.int64) for b in blocks]
    mine = np.flatnonzero(owner == rank)
    ids = union_ids(mine, unique_ids(*[b.ravel() for b in blocks]) if blocks
                     else np.zeros(0, np.int64))
    cells = tuple(CellBlock(t, np.searchsorted(ids, b).reshape(len(b), -1)) for t, b in zip(types, blocks, strict=True))
    counted = tuple(owner[b[:, 0]] == rank if len(b) else np.zeros(0, dtype=bool) for b in blocks)
    pts = np.ascontiguousarray(coordinates(ids), dtype=np.float64).reshape(len(ids), 3)
    return MeshPart(int(n_points), int(n_cells), int(rank), ids, pts, owner[ids] == rank, int(dim), tuple(types),
                    cells, tuple(np.asarray(c, dtype=np.int64) for c in cell_ids), counted)


def part_of(mesh: Mesh, owner: np.ndarray, rank: int) -> MeshPart:
    """The :class:`MeshPart` of ``rank`` of a whole mesh in memory (``owner``: :func:`node_owners`)."""
    cells = [b for b in mesh.cells if len(b)]
    types, blocks, cell_ids, start = [], [], [], 0
    for b in cells:
        mask = touching(b.data, owner, rank)
        types.append(b.type)
        blocks.append(b.data[mask])
        cell_ids.append(start + np.flatnonzero(mask))
        start += len(b)
    return assemble_part(mesh.n_points, start, owner, rank, mesh.dim, types, blocks, cell_ids,
                         lambda ids: mesh.points[ids])


def whole_part(mesh: Mesh) -> MeshPart:
    """The one part of a whole mesh held by one rank (rank 0 of one): every node owned, every
    non-empty cell block counted, cells numbered in the concatenation of those blocks. No copy of
    the points or the cells (what :func:`part_of` with every node owned by rank 0 gives, cheaply)."""
    cells = tuple(b for b in mesh.cells if len(b))
    starts = np.cumsum([0] + [len(b) for b in cells])
    n = mesh.n_points
    return MeshPart(int(n), int(starts[-1]), 0, np.arange(n, dtype=np.int64),
                    np.asarray(mesh.points, dtype=np.float64), np.ones(n, dtype=bool), int(mesh.dim),
                    tuple(b.type for b in cells), cells,
                    tuple(np.arange(a, b, dtype=np.int64) for a, b in zip(starts[:-1], starts[1:], strict=True)),
                    tuple(np.ones(len(b), dtype=bool) for b in cells))


def localize(mesh: Mesh, owner: np.ndarray, rank: int) -> tuple[Mesh, MeshPart]:
    """One rank's local mesh and its part, from a mesh that has every node's coordinates.

    The local mesh keeps the nodes a rank needs and no other: those it owns (``owner``), the halo
    (the other nodes of the cells touching them) and every marker node (the surface and the
    boundaries that every rank's warp and box need). Rows are sorted by global id (so every sum and
    tie-break over them runs in the order of the whole mesh); ``global_ids`` maps rows to global
    ids, ``cells`` (those touching the owned nodes, global order) and ``markers`` use local ids.
    ``mesh`` must have every node and every cell (the part's ``cell_ids`` are indices into its
    cells: of a partial mesh they would be that mesh's own, not the file's). The part's ``rows``
    are its nodes' rows of the local mesh.

    This is the definition every reader by parts must reproduce (``read_part`` of a format gives
    the same local mesh without any rank holding every node).
    """
    part = part_of(mesh, owner, rank)
    marker = [b.data.ravel() for blocks in mesh.markers.values() for b in blocks]
    keep = unique_ids(part.ids, *marker).astype(np.int64)
    rows = np.searchsorted(keep, part.ids)
    local = Mesh(points=mesh.points[keep], dim=mesh.dim,
                 cells=[CellBlock(b.type, rows[b.data]) for b in part.cells],
                 markers={name: [CellBlock(b.type, np.searchsorted(keep, b.data)) for b in blocks]
                          for name, blocks in mesh.markers.items()},
                 path=mesh.path, format=mesh.format, source=mesh.source, partial=True,
                 global_ids=keep, n_global=mesh.n_points)
    return local, replace(part, rows=rows)


def rank_part(mesh: Mesh, comm) -> MeshPart:
    """This rank's part of a whole mesh that every rank holds (``comm``: :mod:`ffdcli.parallel.comm`)."""
    return part_of(mesh, node_owners(mesh.points, comm.size), comm.rank)


def redistribute(comm, owners, types, blocks, cell_ids) -> tuple[list, list]:
    """Cells read in any split sent to every rank that owns one of their nodes (an all-to-all).

    ``blocks``/``cell_ids``: per cell type, the (k, nodes) global node ids and (k,) global indices
    of the cells this rank read; ``owners``: per type, the (k, nodes) owner rank of each of their
    nodes. Returns, per type, the cells touching this rank's nodes, sorted by global index."""
    outgoing = [[] for _ in range(comm.size)]
    for b, c, ow in zip(blocks, cell_ids, owners, strict=True):
        k = len(b)
        ow = ow.reshape(k, b.shape[1])
        lo, hi = ow.min(axis=1, initial=comm.size), ow.max(axis=1, initial=-1)
        cell, dest = np.flatnonzero(lo == hi), lo[lo == hi]       # most cells: one owner
        shared = np.flatnonzero(lo != hi)                         # the others: each (cell, rank) pair once
        if len(shared):
            srt = np.sort(ow[shared], axis=1)
            first = np.ones(srt.shape, dtype=bool)
            first[:, 1:] = srt[:, 1:] != srt[:, :-1]
            cell = np.concatenate([cell, np.repeat(shared, srt.shape[1])[first.ravel()]])
            dest = np.concatenate([dest, srt.ravel()[first.ravel()]])
        order = np.lexsort((cell, dest))                          # by rank, cells in read order within one
        cuts = np.searchsorted(dest[order], np.arange(comm.size + 1))
        for r in range(comm.size):
            sel = cell[order[cuts[r]:cuts[r + 1]]]
            outgoing[r].append((b[sel], c[sel]))
        del ow, lo, hi, cell, dest, order
    own, outgoing[comm.rank] = outgoing[comm.rank], None      # this rank's own cells are not sent
    incoming = comm.alltoall(outgoing)
    incoming[comm.rank] = own
    del outgoing, own
    out_blocks, out_ids = [], []
    for k, t in enumerate(types):
        got = [msg[k] for msg in incoming]
        data = np.concatenate([g[0] for g in got]) if got else np.zeros((0, CELL_NODES[t]), np.int64)
        ids = np.concatenate([g[1] for g in got]) if got else np.zeros(0, np.int64)
        for msg in incoming:
            msg[k] = None
        if np.any(np.diff(ids) < 0):        # read in rows of ranks in rank order: usually sorted already
            order = np.argsort(ids, kind="stable")
            data, ids = data[order], ids[order]
        out_blocks.append(data.reshape(len(ids), CELL_NODES[t]))
        out_ids.append(ids)
    return out_blocks, out_ids


def _ask(comm, bounds: np.ndarray, ids: np.ndarray, answer) -> list:
    """Every rank asks the holders of the blocks of rows (``bounds`` (size + 1,): rank r holds global
    rows ``bounds[r] .. bounds[r + 1] - 1``) about sorted unique global ``ids`` (two all-to-alls):
    ``answer(rows)`` on the holder, with ``rows`` its local row indices, gives an array of one row per
    id. Returns the answers in the order of ``ids``, one array per rank concatenated by the caller."""
    holder = np.searchsorted(bounds, ids, side="right") - 1
    cuts = np.searchsorted(holder, np.arange(comm.size + 1))     # ids sorted: holders nondecreasing
    asked = comm.alltoall([ids[cuts[r]:cuts[r + 1]] for r in range(comm.size)])
    return comm.alltoall([answer(a - bounds[comm.rank]) for a in asked])


def local_mesh_of_blocks(comm, block: np.ndarray, n: int, dim: int, types, blocks, cell_ids, n_cells: int,
                         markers: dict) -> tuple[Mesh, MeshPart]:
    """One rank's local mesh (:func:`localize`, without ``path``, ``format``, ``source``) and its part
    from blocks of rows read by each rank; a collective. No rank holds every node.

    Parameters
    ----------
    block
        (m, 3) this rank's contiguous block of the ``n`` nodes' coordinates (the blocks in rank order
        are the rows in order; any lengths, some empty).
    types, blocks, cell_ids
        The mesh's non-empty cell types in its order (the same on every rank); per type, the (k, nodes)
        cells this rank read (global node ids, any split of the cells) and their (k,) global indices.
        ``blocks`` (a list) is emptied once the cells are sent: drop other references to its arrays
        and they are freed then, before the local mesh is built (the peak memory of a read).
    n_cells
        The mesh's cell count.
    markers
        Every marker, global node ids (the same on every rank).

    Each node goes to its owner (:func:`block_owners`; one all-to-all of ids and coordinates); the
    owners of the nodes of the cells read are asked of the blocks' holders, the cells sent to the
    owners of their nodes (:func:`redistribute`), and the coordinates of the halo and marker nodes
    asked of the holders (all-to-alls of ids, then of rows). Equal to :func:`localize` of the whole
    mesh with :func:`node_owners`, field by field.
    """
    block = np.ascontiguousarray(block, dtype=np.float64).reshape(-1, 3)
    counts = np.array(comm.allgather(len(block)), dtype=np.int64)
    bounds = np.concatenate([[0], np.cumsum(counts)])
    if int(bounds[-1]) != n:
        raise ValueError(f"the ranks' blocks hold {int(bounds[-1])} rows, the mesh has {n} nodes")
    start, rank = int(bounds[comm.rank]), comm.rank
    own = block_owners(comm, block, start, n)
    gid = np.arange(start, start + len(block), dtype=np.int64)
    by = np.argsort(own, kind="stable")
    cut = np.searchsorted(own[by], np.arange(comm.size + 1))
    got = comm.alltoall([(gid[by[cut[r]:cut[r + 1]]], block[by[cut[r]:cut[r + 1]]]) for r in range(comm.size)])
    mine = np.concatenate([g[0] for g in got])           # sorted: the holders' blocks in rank order
    mine_pts = np.concatenate([g[1] for g in got]).reshape(-1, 3)
    # the owners of the nodes of the cells read, from the holders of their rows
    empty = np.zeros(0, np.int64)
    blocks[:] = [np.asarray(b, dtype=np.int64) for b in blocks]
    need = unique_ids(*blocks, empty)
    need_owner = np.concatenate([np.zeros(0, np.int32)] + _ask(comm, bounds, need, lambda rows: own[rows]))
    owners = [need_owner[np.searchsorted(need, b)] for b in blocks]
    del need, need_owner
    read = blocks
    blocks, cell_ids = redistribute(comm, owners, types, read, cell_ids)
    del owners
    read.clear()                 # the cells as read (the caller's list): sent, no longer needed
    # the part: owned nodes and their halo; the local mesh: the part's nodes and every marker node
    ids = unique_ids(mine, *blocks, empty)
    marker = [b.data.ravel() for bl in markers.values() for b in bl]
    keep = unique_ids(ids, *marker, empty).astype(np.int64)
    at = np.searchsorted(mine, keep)
    is_mine = (at < len(mine)) & (mine[np.minimum(at, max(len(mine) - 1, 0))] == keep) if len(mine) else \
        np.zeros(len(keep), dtype=bool)
    points = np.empty((len(keep), 3))
    points[is_mine] = mine_pts[at[is_mine]]
    others = keep[~is_mine]
    asked = _ask(comm, bounds, others, lambda rows: block[rows])
    points[~is_mine] = np.concatenate([np.zeros((0, 3))] + asked).reshape(-1, 3)
    rows = np.searchsorted(keep, ids)
    part_cells, cells, counted = [], [], []
    for k, t in enumerate(types):            # the global-id cells replaced one by one by local ones
        b = blocks[k]
        part_cells.append(CellBlock(t, np.searchsorted(ids, b).reshape(len(b), -1)))
        cells.append(CellBlock(t, rows[part_cells[-1].data]))
        counted.append(is_mine[np.searchsorted(keep, b[:, 0])] if len(b) else np.zeros(0, dtype=bool))
        blocks[k] = b = None
    part = MeshPart(int(n), int(n_cells), int(rank), ids, points[rows], is_mine[rows], int(dim), tuple(types),
                    tuple(part_cells), tuple(np.asarray(c, dtype=np.int64) for c in cell_ids), tuple(counted), rows)
    local = Mesh(points=points, dim=int(dim), cells=cells,
                 markers={name: [CellBlock(b.type, np.searchsorted(keep, b.data)) for b in bl]
                          for name, bl in markers.items()},
                 partial=True, global_ids=keep, n_global=int(n))
    return local, part
