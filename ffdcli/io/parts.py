"""The write of an MPI rank's local mesh: an SU2 file printed by parts, or what rank 0 writes whole.

:func:`rendered_mesh` prints each rank's own point rows of an SU2 file and hands rank 0 the texts;
:func:`writable_mesh` is the mesh rank 0 writes every node of after
:func:`ffdcli.parallel.distributed.gather_points` (docs/mpi.md).
"""

from __future__ import annotations

import numpy as np

from ffdcli.io import formats
from ffdcli.io.formats import su2
from ffdcli.mesh import Mesh
from ffdcli.parallel.distributed import rows_of_block

#: Formats whose writer patches a copy of the input file with the coordinates (``Mesh.source``).
PATCHED = ("su2", "cgns")
#: Bytes of printed SU2 rows a rank sends rank 0 per round of :func:`rendered_mesh`.
RENDER_PIECE = 1 << 26


def rendered_mesh(mesh: Mesh, part, points: np.ndarray, path, comm, *, piece: int = RENDER_PIECE
                  ) -> tuple[bool, Mesh | None]:
    """The SU2 file of a local mesh printed by parts, a collective: ``(True, mesh)`` where ``mesh`` (rank
    0; None on the others) is what rank 0 hands to :func:`ffdcli.io.formats.write_mesh` for ``path``, or
    ``(False, None)`` on every rank when the write cannot be done by parts (then
    :func:`gather_points` and :func:`writable_mesh`).

    By parts when the mesh was read by parts from an SU2 file (every rank holds the layout of the
    point rows it parsed, :func:`ffdcli.io.formats.su2.read_part`), the output is SU2, and the file has
    no SU2 FFD section (whose refresh needs every node). Each rank gets the new coordinates of its
    rows from their owners (:func:`rows_of_block`) and prints them
    (:func:`ffdcli.io.formats.su2.render_rows`): the ``%.17g`` printing, the serial writer's largest
    cost, is split between the ranks. Rank 0 receives the texts in rounds of at most ``piece`` bytes
    a rank (MPI counts stay below 2**31) and keeps them in file order: about the bytes of the point
    block (~60 bytes a moved row), where the gather held 24 bytes a node plus the 48 bytes a node of
    the whole block's layout.
    """
    src = mesh.source
    ok = (mesh.global_ids is not None and mesh.format == "su2" and isinstance(src, su2.Su2Source)
          and src.block is not None and formats.format_of(path) == "su2")
    if not all(comm.allgather(ok)) or comm.root_then_bcast(su2.has_ffd_section, mesh.path, src):
        return False, None
    block = comm.run(rows_of_block, part, points, src.first_row, len(src.points), comm)
    text = comm.run(su2.render_rows, mesh.path, src, block)
    del block
    rounds = max(comm.allgather(-(-len(text) // piece)))
    pieces: list[list[np.ndarray]] = [[] for _ in range(comm.size)]
    chunk = got = None
    for k in range(rounds):
        chunk = text[k * piece:(k + 1) * piece]
        lengths = comm.allgather(len(chunk))
        got = comm.gather_rows(chunk)
        if comm.is_root:
            for r, (a, b) in enumerate(zip(np.cumsum([0] + lengths[:-1]), np.cumsum(lengths), strict=True)):
                if b > a:
                    pieces[r].append(got[a:b])
    del text, chunk, got             # rank 0 keeps the received copies only
    if not comm.is_root:
        return True, None
    rendered = su2.Su2Rendered(ndim=src.ndim, text=tuple(p for per in pieces for p in per),
                               block_start=src.block_start, block_end=src.block_end, size=src.size,
                               mtime_ns=src.mtime_ns)
    shape_only = np.broadcast_to(np.zeros(3), (int(mesh.n_global), 3))
    return True, Mesh(points=shape_only, dim=mesh.dim, path=mesh.path, format="su2", source=rendered, partial=True)


def writable_mesh(mesh: Mesh, path) -> Mesh:
    """The mesh rank 0 writes every node of (N, 3) to ``path`` with :func:`ffdcli.io.formats.write_mesh`.

    A mesh with every node is itself. Of a local mesh: when the output is the input's format and
    the reader left the writer the layout of the input file (SU2's point block, CGNS's coordinate
    arrays, ``source``), a copy of the file is patched, so only the input's path, format and layout
    are needed (a mesh of no cells, shaped as every node); any other output is written from
    scratch, from the whole file read again (rank 0 only, at write time)."""
    if mesh.global_ids is None:
        return mesh
    if mesh.format in PATCHED and mesh.source is not None and formats.format_of(path) == mesh.format:
        shape_only = np.broadcast_to(np.zeros(3), (int(mesh.n_global), 3))     # no memory: the writers read
        return Mesh(points=shape_only, dim=mesh.dim, path=mesh.path, format=mesh.format,    # the file's copy
                    source=mesh.source, partial=True)
    return formats.read_mesh(mesh.path)
