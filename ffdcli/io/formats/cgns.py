"""CGNS meshes (HDF5 container, read with h5py; ADF through ``adf2hdf``).

Reading walks the CGNS tree by the ``label`` attribute of each node (``CGNSBase_t``, ``Zone_t``,
``GridCoordinates_t``, ``Elements_t``, ``ZoneBC_t``, ``BC_t``, ``FamilyName_t``, ...), never by the
names a particular mesher gives its nodes. Only the node names that the CGNS standard (SIDS) fixes
are looked up by name: ``CoordinateX/Y/Z``, ``ElementRange``, ``ElementConnectivity``,
``ElementStartOffset``, ``PointList``, ``PointRange``, ``ElementList``, ``ElementRange``.

Conventions of the :class:`~ffdcli.mesh.Mesh` returned by :func:`read`:

- **Point ids.** The points of every zone of every base are concatenated in file order (the order
  in which the zones were written, which HDF5 keeps); zone ``z`` owns ids
  ``source.zones[z].offset ... offset + n_points - 1``. A structured zone numbers its vertices with
  ``i`` fastest (CGNS/Fortran order): id = offset + i + ni*(j + nj*k), 0-based.
- **One-to-one interfaces are not merged**: a point on a block interface appears once per zone.
  Moving all copies with the same deformation keeps the interface conforming.
- **Cells.** Unstructured elements of the base's cell dimension become interior cells, in VTK node
  order: CGNS and VTK agree for the linear types except the prism (``PENTA_6``), whose two triangles
  are reversed (:data:`WEDGE_CGNS_TO_VTK`, both ways). Higher-order elements keep their corner nodes.
  ``MIXED`` sections are split by type and by dimension (their faces are boundary elements).
  ``NGON_n``/``NFACE_n`` sections are read as polyhedral cells (:mod:`ffdcli.io.formats.cgns_ngon`,
  ``mesh.polyhedra``; the standard volume cells of other zones then become polyhedra too, one cell
  model per mesh). An element type ffd cannot read is an InputError naming the section, never skipped.
  Structured zones become hexahedra (3D) or quads, mirrored for a left-handed block so that cell
  volumes (areas of a planar 2D mesh) are positive; quads of a surface in space keep the file's
  orientation.
- **Markers** come from the ``BC_t`` nodes. A BC is named by its ``FamilyName`` when it has one (that
  is the name CFD solvers group boundary conditions by, e.g. ``WALL`` for ``BC1_on_WALL``) unless the
  family is a placeholder (``Unspecified``, ``UnspecifiedBC``, ``Null``, empty); otherwise by the BC
  name. BCs sharing a family (or the same name in several zones) are one marker. The markers by BC
  name are kept in ``source.bc_markers`` (see :func:`markers_by_bc`). A BC given by points
  (``GridLocation`` Vertex) of an unstructured zone becomes the boundary faces whose nodes are
  exactly its points when such faces exist, else one ``vertex`` block; a BC given by elements
  (``ElementList``/``ElementRange``, or a point list/range with a face/edge ``GridLocation``) takes
  those boundary elements. Structured BCs (``PointRange``) become the quads (lines in 2D) of the
  range, quads on a block side pointing out of the block; a range that is not a face (an edge, a
  ``PointList``) is a ``vertex`` block.
  Boundary sections (elements of a lower dimension than the base) that no BC refers to are markers
  named by the section. A surface mesh (base cell dimension 2 in 3D space) also gets one marker named
  after its base holding all its cells, so that the whole surface can be selected.

Writing a mesh read from CGNS copies the input file and replaces only the coordinate arrays
(``CoordinateX/Y/Z`` data of the grid read) of every zone, in their stored precision; everything
else is unchanged. An ADF input is written as CGNS/HDF5 (the container every current CGNS reader
accepts; ``hdf2adf`` converts it back if needed). A mesh from another format is written from
scratch as an unstructured CGNS/HDF5 file: one base, one zone, one section per cell block and per
marker, one ``BC_t`` per marker (``PointList`` of its elements, or of its points for a marker that
has only ``vertex`` blocks; the vertex blocks of a marker that also has faces are not written).
The coordinates are R8, a 2D mesh whose z is 0 is written with PhysicalDimension 2 (x, y only).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli.deferred import deferred
from ffdcli.errors import InputError
from ffdcli.io.formats import cgns_ngon
from ffdcli.io.formats.cgns_bc import (  # noqa: F401
    PLACEHOLDER_FAMILIES,
    MarkerSet,
    bc_marker_name,
    markers_by_bc,
    structured_bc,
    unstructured_bc,
)
from ffdcli.io.formats.cgns_cells import (  # noqa: F401  (the cell readers; tests reach them here too)
    CGNS_CODE,
    ELEMENT_TYPES,
    MIXED,
    NFACE_N,
    NGON_N,
    TYPE_ORDER,
    WEDGE_CGNS_TO_VTK,
    Section,
    handedness,
    mixed_offsets,
    mixed_offsets_reference,
    nodes_per_type_table,
    orient_structured,
    range_faces,
    read_element_section,
    sections_cells,
    structured_cells,
    structured_ids,
)
from ffdcli.io.formats.cgns_nodes import (  # noqa: F401
    ADF_MARK,
    HDF5_SIGNATURE,
    CgnsSource,
    CgnsZone,
    adf_message,
    char_array,
    check_no_links,
    child_text,
    children_of,
    container_of,
    convert_adf,
    data_of,
    index_data,
    label_of,
    new_node,
    str_attr,
    text_of,
)
from ffdcli.io.formats.cgns_write import write  # noqa: F401  (the format's writer: formats.write_mesh calls cgns.write)
from ffdcli.io.formats.common import MESH_FORMATS, MeshFormat, check_finite_rows
from ffdcli.mesh import CELL_DIM, CELL_NODES, CellBlock, Mesh
from ffdcli.mesh.polyhedra import concat_polyhedra, polyhedra_from_cells
from ffdcli.parallel.partition import local_mesh_of_blocks, localize, node_owners

h5py = deferred("h5py")


def _zone_size(base, zn, file: Path) -> tuple[int, int, bool, tuple[int, ...], int]:
    """(cell dimension, physical dimension, structured, vertex shape, point count) of a zone."""
    bdata = np.asarray(data_of(base)).ravel() if data_of(base) is not None else np.array([3, 3])
    cell_dim, phys_dim = int(bdata[0]), int(bdata[-1])
    ztype = child_text(zn, "ZoneType_t") or "Unstructured"
    zsize = data_of(zn)
    if zsize is None:
        raise InputError("zone without its size data", path=file, key=zn.name)
    zsize = np.asarray(zsize, dtype=np.int64)
    structured = ztype.lower() == "structured"
    if structured:
        vshape = tuple(int(v) for v in zsize.reshape(3, -1)[0]) if zsize.size % 3 == 0 \
            else tuple(int(v) for v in zsize.ravel()[: cell_dim])
        n_points = int(np.prod(vshape))
    else:
        n_points = int(zsize.ravel()[0])
        vshape = (n_points,)
    return cell_dim, phys_dim, structured, vshape, n_points


def _read_coordinates(zone_node, n_points: int, vertex_shape, phys_dim: int, file: Path, offset: int,
                      structured: bool, span: tuple[int, int] | None = None) -> tuple[np.ndarray, CgnsZone]:
    """The zone's (n_points, 3) coordinates, or only rows ``span = (a, b)`` of an unstructured zone
    (a hyperslab of each coordinate array), and its :class:`CgnsZone`."""
    grids = children_of(zone_node, "GridCoordinates_t")
    if not grids:
        raise InputError("zone has no GridCoordinates_t node (no point coordinates)", path=file,
                         key=zone_node.name)
    grid = next((g for g in grids if g.name.rsplit("/", 1)[-1] == "GridCoordinates"), grids[0])
    rind = children_of(grid, "Rind_t")
    if rind and np.any(np.asarray(data_of(rind[0])) != 0):
        raise InputError("grid coordinates with rind (ghost) planes are not supported", path=file,
                         key=rind[0].name)
    arrays = {c.name.rsplit("/", 1)[-1]: c for c in children_of(grid, "DataArray_t")}
    names = ["CoordinateX", "CoordinateY", "CoordinateZ"]
    need = names[:max(phys_dim, 2)]
    missing = [n for n in need if n not in arrays or " data" not in arrays[n]]
    if missing:
        have = ", ".join(arrays) or "none"
        raise InputError(f"missing {', '.join(missing)} (Cartesian coordinates expected; the grid has: "
                         f"{have})", path=file, key=grid.name)
    a, b = (0, n_points) if span is None else span
    pts = np.zeros((b - a, 3))
    paths = []
    for axis, name in enumerate(names):
        if name not in arrays or " data" not in arrays[name]:
            continue
        ds = arrays[name][" data"]
        if ds.size != n_points:
            raise InputError(f"{name} has {ds.size} values, the zone has {n_points} points", path=file,
                             key=f"{arrays[name].name}/ data")
        if structured and ds.shape != tuple(vertex_shape)[::-1]:
            # HDF5 holds the Fortran-ordered CGNS array with its dimensions reversed: (nk, nj, ni)
            raise InputError(f"{name} has shape {tuple(ds.shape)[::-1]}, the zone has "
                             f"{tuple(vertex_shape)} vertices", path=file, key=f"{arrays[name].name}/ data")
        if span is None:
            pts[:, axis] = np.asarray(ds[()], dtype=np.float64).ravel()
        elif b > a:                 # a hyperslab: this rank's rows only
            pts[:, axis] = np.asarray(ds[a:b] if ds.ndim == 1 else ds[()], dtype=np.float64).ravel()[
                slice(None) if ds.ndim == 1 else slice(a, b)]
        paths.append(f"{arrays[name].name}/ data")   # ds.name would be the path inside a linked file
    zone = CgnsZone(zone_node.name, tuple(paths), offset, n_points, structured,
                    tuple(int(s) for s in vertex_shape))
    return pts, zone


def _unstructured_zone(zn, pts, zone, offset, n_points, cell_dim, phys_dim, file, share, ms, polys,
                       section_markers) -> list:
    """The interior cell blocks of an unstructured zone (whole, or one MPI rank's :class:`_Rows`); its
    boundary conditions go into ``ms``, its polyhedra into ``polys``, and the boundary faces of its
    sections that no BC names into ``section_markers`` (markers named after the section)."""
    zone_blocks: list = []
    sections, in_order = [], []      # in_order: per Elements_t, its _Rows or its index in sections
    for sec in children_of(zn, "Elements_t"):
        rows = _interior_rows(sec, offset, n_points, cell_dim, file, share) \
            if share is not None and cell_dim in (phys_dim, 3) else None
        if rows is not None:        # one rank's rows of a volume section (BCs never name them)
            in_order.append(rows)
            continue
        in_order.append(len(sections))
        sections.append(read_element_section(sec, offset, n_points, file))
    poly = cgns_ngon.zone_polyhedra(sections, pts, offset, cell_dim, file)
    if poly is not None:
        polys.append(poly)
    used: set[int] = set()
    for zbc in children_of(zn, "ZoneBC_t"):
        for bc in children_of(zbc, "BC_t"):
            bc_name, name = bc_marker_name(bc)
            ms.add_bc(bc_name, name, unstructured_bc(bc, zone, sections, cell_dim, file, used))
    for si in in_order:
        if isinstance(si, _Rows):
            zone_blocks.append(si)
            continue
        s = sections[si]
        if isinstance(s, cgns_ngon.PolySection):       # polyhedra: read above, never a marker
            continue
        # a MIXED section may hold both volume cells and boundary faces: split by dimension
        inner = [CellBlock(t, s.blocks[t]) for t in TYPE_ORDER
                 if t in s.blocks and CELL_DIM[t] >= cell_dim]
        outer = [CellBlock(t, s.blocks[t]) for t in TYPE_ORDER
                 if t in s.blocks and CELL_DIM[t] < cell_dim]
        zone_blocks.extend(inner)
        if outer and si not in used:
            section_markers.append((s.name, outer))
    return zone_blocks


def _markers(ms, section_markers, surface_cells) -> dict:
    """The markers of the file: its BCs, then the boundary sections no BC names, then the surface
    zones of a surface mesh in space (by base name)."""
    markers = ms.markers
    for name, blocks in section_markers:
        if name in ms.from_bc:
            continue
        markers.setdefault(name, []).extend(blocks)
    for name, parts in surface_cells.items():
        # a planar 2D mesh stored with a constant third coordinate is not a surface in space
        every = np.vstack([p for p, _ in parts])
        if name not in markers and np.all(np.ptp(every, axis=0) > 0):
            markers[name] = _merge([b for _, blocks in parts for b in blocks])
    return {k: _merge(v) for k, v in markers.items()}


def _read_tree(h5: h5py.File, file: Path, container: str, progress, share=None) -> Mesh:
    """The mesh of the file. ``share`` (``share(n) -> (a, b)``, one MPI rank's): the interior cells
    are read as rows ``[a, b)`` of each section / zone (hyperslabs of ``ElementConnectivity``),
    ``mesh.cells`` is then a list of :class:`_Rows`, and the result is ``(mesh, rows)``: ``rows`` the
    rank's block ``(a, b)`` of the points when ``mesh.points`` holds only those (unstructured volume
    zones only), else None (every point; see :func:`read_part`)."""
    bases = children_of(h5, "CGNSBase_t")
    if not bases:
        raise InputError("no CGNSBase_t node: not a CGNS file", path=file, key="/")
    zones_nodes = [(b, z) for b in bases for z in children_of(b, "Zone_t")]
    if not zones_nodes:
        raise InputError("the CGNS file has no Zone_t node", path=file, key=bases[0].name)
    points: list[np.ndarray] = []
    cells: dict[str, list[np.ndarray]] = {}
    ms = MarkerSet()
    zones: list[CgnsZone] = []
    skipped: list[str] = []
    polys: list = []
    surface_cells: dict[str, list[tuple[np.ndarray, list[CellBlock]]]] = {}
    section_markers: list[tuple[str, list[CellBlock]]] = []
    offset = 0
    dim = 0
    bar = progress("reading CGNS zones", len(zones_nodes)) if progress else None
    sizes = [_zone_size(base, zn, file) for base, zn in zones_nodes]
    if share is not None:        # polyhedral cells need the whole mesh (every rank sees the same tree)
        for _, zn in zones_nodes:
            for sec in children_of(zn, "Elements_t"):
                head = data_of(sec)
                if head is not None and int(np.asarray(head).ravel()[0]) in (cgns_ngon.NGON_N, cgns_ngon.NFACE_N):
                    raise WholeMeshNeeded(zn.name)
    if share is not None and all(not z[2] and z[0] >= z[1] for z in sizes):
        # unstructured volume zones only: this rank reads its block of the points (hyperslabs of
        # the coordinate arrays); structured zones (their orientation) and surfaces need them all
        point_rows = share(sum(z[4] for z in sizes))
    else:
        point_rows = None
    for (base, zn), (cell_dim, phys_dim, structured, vshape, n_points) in zip(zones_nodes, sizes, strict=True):
        dim = max(dim, cell_dim)
        check_no_links(zn, file)
        for grid in children_of(zn, "GridCoordinates_t"):
            check_no_links(grid, file)
        span = None if point_rows is None else tuple(min(max(e - offset, 0), n_points) for e in point_rows)
        pts, zone = _read_coordinates(zn, n_points, vshape, phys_dim, file, offset, structured, span)
        zone_blocks: list[CellBlock] = []
        if structured:
            blk = structured_cells(vshape, offset)
            handed = 0
            if blk is not None:
                handed = handedness(blk, pts, offset)
                zone_blocks.append(orient_structured(blk, pts, offset))
            for zbc in children_of(zn, "ZoneBC_t"):
                for bc in children_of(zbc, "BC_t"):
                    bc_name, name = bc_marker_name(bc)
                    ms.add_bc(bc_name, name, structured_bc(bc, zone, file, handed))
        else:
            zone_blocks = _unstructured_zone(zn, pts, zone, offset, n_points, cell_dim, phys_dim, file, share, ms,
                                             polys, section_markers)
        for b in zone_blocks:
            if share is not None and not isinstance(b, _Rows):      # read whole: keep this rank's rows
                a, e = share(len(b))
                b = _Rows(b.type, len(b), a, b.data[a:e])
            cells.setdefault(b.type, []).append(b if share is not None else b.data)
        if cell_dim < phys_dim and zone_blocks:
            surface_cells.setdefault(base.name.rsplit("/", 1)[-1], []).append((pts, zone_blocks))
        points.append(pts)
        zones.append(zone)
        offset += n_points
        if bar:
            bar.update(1)
    if bar:
        bar.close()
    markers = _markers(ms, section_markers, surface_cells)
    cell_blocks = ([CellBlock(t, np.vstack(cells[t])) for t in TYPE_ORDER if t in cells] if share is None
                   else [r for t in TYPE_ORDER for r in cells.get(t, [])])
    polyhedra = None
    if polys:           # one cell model for the mesh: the other zones' volume cells become polyhedra too
        volume = [b for b in cell_blocks if CELL_DIM[b.type] == 3]
        if volume:
            polys.append(polyhedra_from_cells(volume)[0])
        polyhedra = concat_polyhedra(polys)
        cell_blocks = [b for b in cell_blocks if CELL_DIM[b.type] != 3]
    source = CgnsSource(container, zones, {k: _merge(v) for k, v in ms.by_bc.items()}, ms.bc_family,
                        skipped)
    mesh = Mesh(points=np.vstack(points), dim=dim, cells=cell_blocks, markers=markers, path=file,
                format="cgns", source=source, polyhedra=polyhedra)
    return mesh if share is None else (mesh, point_rows)


@dataclass
class _Rows:
    """Rows ``[start, start + len(data))`` of ``n`` cells of one type (a section or zone) that one
    rank read (global 0-based node ids, VTK order)."""

    type: str
    n: int
    start: int
    data: np.ndarray

    def __len__(self) -> int:
        return self.n


def _interior_rows(sec, offset: int, n_points: int, cell_dim: int, file: Path, share) -> _Rows | None:
    """This rank's rows of an Elements_t node of volume cells of one type, read as a hyperslab of
    its connectivity; None for anything else (MIXED, faces, polyhedra, unknown types: read whole)."""
    head = data_of(sec)
    rng = index_data(sec, "ElementRange")
    node = sec.get("ElementConnectivity")
    ds = node.get(" data") if isinstance(node, h5py.Group) else None
    if head is None or rng is None or rng.size != 2 or ds is None:
        return None
    code = int(np.asarray(head).ravel()[0])
    if code not in ELEMENT_TYPES or CELL_DIM[ELEMENT_TYPES[code][0]] < cell_dim:
        return None
    t, npe = ELEMENT_TYPES[code]
    start, end = (int(v) for v in rng.ravel())
    n = end - start + 1
    if ds.size != n * npe:
        raise InputError(f"ElementConnectivity has {ds.size} entries, expected {n} x {npe}",
                         path=file, key=sec.name)
    a, b = share(n)
    ids = np.asarray(ds[a * npe:b * npe], dtype=np.int64).reshape(b - a, npe)[:, :CELL_NODES[t]] - 1
    if t == "wedge":
        ids = ids[:, WEDGE_CGNS_TO_VTK]
    if len(ids) and (ids.min() < 0 or ids.max() >= n_points):
        raise InputError(f"element connectivity refers to point ids outside 1..{n_points}",
                         path=file, key=sec.name)
    return _Rows(t, n, a, ids + offset)


class WholeMeshNeeded(Exception):  # noqa: N818 - not an error: a signal to read_part
    """Raised by a read by parts that met NGON_n/NFACE_n (polyhedral) cells: polyhedra are defined by
    the whole face list, so the mesh is read whole (:func:`read_part`)."""


def read_part(path: str | Path, comm, progress=None):
    """One MPI rank's read of a CGNS/HDF5 mesh: ``(mesh, part)``, its local mesh and part; a collective.

    Every rank reads the boundary (markers, whole) and of the volume cells only its share of the
    rows of each section, as hyperslabs of ``ElementConnectivity`` (MIXED sections and structured
    zones are read or built whole and cut the same way). When every zone is an unstructured volume
    zone, each rank also reads only its block of the points (hyperslabs of ``CoordinateX/Y/Z``);
    structured zones (whose cells are oriented by a vote over all of them) and surface meshes are
    read with every point by every rank, transiently. Then
    (:func:`ffdcli.parallel.partition.local_mesh_of_blocks`) each node goes to its owner, the cells to the
    owners of their nodes, and the halo and marker nodes' coordinates are asked of the ranks that
    read them. ``mesh`` is the rank's local mesh (:func:`ffdcli.parallel.partition.localize` of :func:`read`'s
    mesh), ``part`` its :class:`~ffdcli.parallel.partition.MeshPart`; ``mesh.source`` (zones, paths: small) on
    every rank. An ADF file is read by rank 0, broadcast and localized. A mesh with NGON_n/NFACE_n
    (polyhedral) zones is read by rank 0 and broadcast, and stays whole on every rank: ``part`` is
    then None (as for an OpenFOAM case, :func:`ffdcli.io.formats.read_part`).
    """
    p = Path(path)
    if comm.run(container_of, p) == "adf":
        mesh = comm.root_then_bcast(read, p, progress)
        return localize(mesh, node_owners(mesh.points, comm.size), comm.rank)

    def parse():
        try:
            h5 = h5py.File(p, "r")
        except OSError as exc:
            raise InputError(f"cannot open as CGNS/HDF5: {exc}", path=p) from None
        with h5:
            try:
                mesh, got = _read_tree(h5, p, "hdf5", progress, share=comm.share)
            except WholeMeshNeeded:          # every rank sees the same tree: the same answer on every rank
                return None
            except (KeyError, OSError, ValueError, TypeError, IndexError) as exc:
                raise InputError(f"corrupt or unsupported CGNS file: {exc}", path=p) from None
        n = sum(z.n_points for z in mesh.source.zones)
        a, b = comm.share(n) if got is None else got
        return mesh, np.ascontiguousarray(mesh.points if got is not None else mesh.points[a:b]), a, n

    got = comm.run(parse)
    if got is None:
        return comm.root_then_bcast(read, p, progress), None
    mesh, block, a, n = got
    check_finite_rows(comm, block, a, p)         # before the owners (Morton codes of finite points)
    rows = mesh.cells
    types, blocks, ids, start = [], [], [], 0
    for t in TYPE_ORDER:                   # the serial blocks: one per type, sections in file order
        mine = [r for r in rows if r.type == t]
        if not mine or not sum(r.n for r in mine):
            continue
        parts, base = [], start
        for r in mine:
            parts.append(base + r.start + np.arange(len(r.data), dtype=np.int64))
            base += r.n
        types.append(t)
        blocks.append(np.vstack([r.data for r in mine]))
        ids.append(np.concatenate(parts))
        start = base
    mesh.cells = []
    del rows, mine                   # the rows as read (local_mesh_of_blocks empties blocks once sent)
    local, part = local_mesh_of_blocks(comm, block, n, mesh.dim, types, blocks, ids, start, mesh.markers)
    local.path, local.format, local.source = mesh.path, mesh.format, mesh.source
    return local, part


def _merge(blocks: list[CellBlock]) -> list[CellBlock]:
    """One block per cell type, in a fixed type order, keeping the order of the cells."""
    by: dict[str, list[np.ndarray]] = {}
    for b in blocks:
        by.setdefault(b.type, []).append(b.data)
    return [CellBlock(t, np.vstack(by[t])) for t in TYPE_ORDER if t in by]


def read(path: str | Path, progress=None) -> Mesh:
    """Read a CGNS mesh (HDF5; ADF when ``adf2hdf`` is on the PATH). See the module docstring."""
    p = Path(path)
    container = container_of(p)
    if container == "adf":
        with tempfile.TemporaryDirectory(prefix="ffd-cgns-") as tmp:
            h5path = Path(tmp) / "converted.cgns"
            convert_adf(p, h5path)
            return _read_file(h5path, p, "adf", progress)
    return _read_file(p, p, "hdf5", progress)


def _read_file(h5path: Path, file: Path, container: str, progress) -> Mesh:
    try:
        h5 = h5py.File(h5path, "r")
    except OSError as exc:
        raise InputError(f"cannot open as CGNS/HDF5: {exc}", path=file) from None
    with h5:
        try:
            return _read_tree(h5, file, container, progress)
        except (KeyError, OSError, ValueError, TypeError, IndexError) as exc:
            # h5py/NumPy errors on damaged nodes (truncated file, wrong shapes): one line, no traceback
            raise InputError(f"corrupt or unsupported CGNS file: {exc}", path=file) from None


# ----------------------------------------------------------------------------------------------
# writing


# -- from scratch ------------------------------------------------------------------------------


MESH_FORMATS.register(MeshFormat("cgns", (".cgns",), "a CGNS/HDF5 mesh", read, write, read_part))
