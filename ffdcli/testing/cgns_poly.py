"""CGNS files of polyhedral cells (NGON_n/NFACE_n) for the tests (fixtures, not the pipeline).

:func:`write_ngon_cgns` writes points and a :class:`~ffdcli.mesh.polyhedra.Polyhedra` as one
unstructured zone: one NGON_n section with every face, one NFACE_n section with every cell (signed
face ids: negative where the face points into the cell, as CGNS 4 asks; ``signed=False`` writes
them all positive, as some older writers do), and one boundary condition per patch naming its faces
(``ElementList``, FaceCenter). ``counted=True`` writes CGNS 3's counted records instead of
``ElementStartOffset``.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from ffdcli.io.formats.cgns_nodes import char_array, new_node, str_attr

NGON_N, NFACE_N = 22, 23


def write_ngon_cgns(path: str | Path, points: np.ndarray, poly, patches, *, signed: bool = True,
                    counted: bool = False) -> Path:
    """Write the CGNS/HDF5 file (see the module). ``patches``: objects with ``name``, ``start``,
    ``n_faces`` (face ranges of ``poly``, as OpenFOAM's)."""
    pts = np.asarray(points, dtype=np.float64)
    nf, nc = poly.n_faces, poly.n_cells
    path = Path(path)
    with h5py.File(path, "w", track_order=True) as h5:
        str_attr(h5, "label", "Root Node of HDF5 File", 33)
        str_attr(h5, "name", "HDF5 MotherNode", 33)
        str_attr(h5, "type", "MT", 3)
        h5.create_dataset(" format", data=char_array("IEEE_LITTLE_32\0"))
        new_node(h5, "CGNSLibraryVersion", "CGNSLibraryVersion_t", "R4", np.array([4.2], dtype=np.float32))
        base = new_node(h5, "Base", "CGNSBase_t", "I4", np.array([3, 3], dtype=np.int32))
        zone = new_node(base, "Zone", "Zone_t", "I8", np.array([[len(pts)], [nc], [0]], dtype=np.int64))
        new_node(zone, "ZoneType", "ZoneType_t", "C1", char_array("Unstructured"))
        grid = new_node(zone, "GridCoordinates", "GridCoordinates_t")
        for a, name in enumerate(["CoordinateX", "CoordinateY", "CoordinateZ"]):
            new_node(grid, name, "DataArray_t", "R8", np.ascontiguousarray(pts[:, a]))
        _section(zone, "Faces", NGON_N, 1, nf, poly.face_nodes + 1, poly.face_offsets, counted)
        offsets, faces, signs = _cells(poly)
        values = (faces + 1) * (signs if signed else 1)
        _section(zone, "Cells", NFACE_N, nf + 1, nf + nc, values, offsets, counted)
        zbc = new_node(zone, "ZoneBC", "ZoneBC_t")
        for p in patches:
            bc = new_node(zbc, p.name, "BC_t", "C1", char_array("BCWall" if p.type == "wall" else "BCFarfield"))
            new_node(bc, "GridLocation", "GridLocation_t", "C1", char_array("FaceCenter"))
            new_node(bc, "PointList", "IndexArray_t", "I8",
                  (np.arange(p.start, p.start + p.n_faces, dtype=np.int64) + 1)[:, None])
    return path


def _cells(poly):
    """Each cell's faces (CSR) and the sign of each: +1 owner (the face points out), -1 neighbour."""
    inner = np.flatnonzero(poly.neighbour >= 0)
    cells = np.concatenate([poly.owner, poly.neighbour[inner]])
    faces = np.concatenate([np.arange(poly.n_faces), inner])
    signs = np.concatenate([np.ones(poly.n_faces, np.int64), -np.ones(len(inner), np.int64)])
    order = np.argsort(cells, kind="stable")
    offsets = np.zeros(poly.n_cells + 1, dtype=np.int64)
    np.cumsum(np.bincount(cells, minlength=poly.n_cells), out=offsets[1:])
    return offsets, faces[order], signs[order]


def _section(zone, name, code, start, end, values, offsets, counted):
    sec = new_node(zone, name, "Elements_t", "I4", np.array([code, 0], dtype=np.int32))
    new_node(sec, "ElementRange", "IndexRange_t", "I8", np.array([start, end], dtype=np.int64))
    if counted:
        size = np.diff(offsets)
        conn = np.insert(np.asarray(values, dtype=np.int64), offsets[:-1], size)
        new_node(sec, "ElementConnectivity", "DataArray_t", "I8", conn)
    else:
        new_node(sec, "ElementStartOffset", "DataArray_t", "I8", np.asarray(offsets, dtype=np.int64))
        new_node(sec, "ElementConnectivity", "DataArray_t", "I8", np.asarray(values, dtype=np.int64))
