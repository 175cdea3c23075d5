"""Writing CGNS: the input file copied with its ``GridCoordinates`` patched (everything else kept),
or a new HDF5 CGNS file (one unstructured zone, the markers as element sections and BCs).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from ffdcli.deferred import deferred
from ffdcli.errors import InputError
from ffdcli.io.atomic import atomic_path
from ffdcli.io.formats.cgns_cells import CGNS_CODE, MIXED, WEDGE_CGNS_TO_VTK
from ffdcli.io.formats.cgns_nodes import CgnsSource, char_array, convert_adf, new_node, str_attr
from ffdcli.io.room import check_room
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.mesh.idsets import unique_ids

h5py = deferred("h5py")


def write(mesh: Mesh, path: str | Path, points: np.ndarray, progress=None) -> None:
    """Write ``mesh`` with coordinates ``points`` to ``path`` (CGNS/HDF5), atomically.

    A mesh read from CGNS: a copy of its file with only the coordinates replaced. Otherwise a new
    unstructured file (see the module docstring).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape != mesh.points.shape:
        raise ValueError(f"points {pts.shape} do not match the mesh {mesh.points.shape}")
    if mesh.format == "cgns" and isinstance(mesh.source, CgnsSource) and mesh.path is not None:
        _write_patched(mesh, Path(path), pts)
    else:
        _write_new(mesh, Path(path), pts)


def _write_patched(mesh: Mesh, path: Path, pts: np.ndarray) -> None:
    src: CgnsSource = mesh.source
    inp = Path(mesh.path)
    if not inp.exists():
        raise InputError("the mesh's input file is gone; cannot copy it to write the output", path=inp)
    with atomic_path(path) as tmp:
        if src.container == "adf":
            tmp.unlink()
            convert_adf(inp, tmp)
        else:
            shutil.copyfile(inp, tmp)
        with h5py.File(tmp, "r+") as h5:
            for zone in src.zones:
                block = pts[zone.offset: zone.offset + zone.n_points]
                for dpath in zone.coordinates:
                    axis = "XYZ".index(dpath.rsplit("/", 2)[-2][-1])
                    ds = h5.get(dpath)
                    if ds is not None and Path(ds.file.filename).resolve() != Path(tmp).resolve():
                        raise InputError("the coordinates are in another file (an HDF5 link); writing "
                                         "them would change that file", path=inp, key=dpath)
                    if ds is None or ds.size != zone.n_points:
                        raise InputError("the input file changed since it was read (coordinates "
                                         "differ)", path=inp, key=dpath)
                    ds[...] = block[:, axis].astype(ds.dtype).reshape(ds.shape)


#: HDF5's own bytes per CGNS node (a group, its attributes, its data set), and of the file: twice what
#: the files this writer makes hold (about 430 bytes an HDF5 object, two objects a node).
NODE_BYTES = 2048
FILE_BYTES = 16384


def new_file_bytes(mesh: Mesh, phys: int, int_size: int) -> int:
    """An upper estimate of the size of the new CGNS file of ``mesh``: its arrays and HDF5's overhead."""
    cells = [b for b in mesh.cells] + [b for v in mesh.markers.values() for b in v]
    ints = sum(b.data.size + len(b) for b in cells)          # connectivity, and MIXED's type codes
    nodes = 12 + 3 * len(mesh.cells) + 6 * len(mesh.markers)
    return len(mesh.points) * phys * 8 + ints * int_size + nodes * NODE_BYTES + FILE_BYTES


def _check_names(mesh: Mesh, path: Path) -> None:
    for name in mesh.markers:
        if not name or len(name.encode("ascii", "replace")) > 32 or "/" in name or name in (".", ".."):
            raise InputError("this marker name cannot be a CGNS node name (1 to 32 characters, no '/')",
                             path=path, key=name)
        if not name.isascii():
            raise InputError("CGNS node names must be ASCII", path=path, key=name)


def _write_new(mesh: Mesh, path: Path, pts: np.ndarray) -> None:
    _check_names(mesh, path)
    n = len(pts)
    flat2d = mesh.dim == 2 and np.all(pts[:, 2] == 0.0)
    phys = 2 if flat2d else 3
    cell_dim = max(mesh.dim, 1)
    total_cells = mesh.n_cells + sum(len(b) for v in mesh.markers.values() for b in v
                                     if b.type != "vertex")
    itype, idt = ("I8", np.int64) if max(n, total_cells) >= 2**31 - 1 else ("I4", np.int32)
    # checked before: a write that fails inside HDF5 leaves its objects in a state that crashes the
    # interpreter at exit, so the failure (the output plan's one line) must come first
    check_room(path, new_file_bytes(mesh, phys, np.dtype(idt).itemsize))
    with atomic_path(path) as tmp, h5py.File(tmp, "w", track_order=True) as h5:
        str_attr(h5, "label", "Root Node of HDF5 File", 33)
        str_attr(h5, "name", "HDF5 MotherNode", 33)
        str_attr(h5, "type", "MT", 3)
        h5.create_dataset(" format", data=char_array("IEEE_LITTLE_32\0"))
        h5.create_dataset(" hdf5version", data=np.frombuffer(
            f"HDF5 Version {'.'.join(map(str, h5py.version.hdf5_version_tuple))}".encode().ljust(33, b"\0"),
            dtype=np.int8))
        # version 3.4: what Debian's CGNS (cgnscheck, cgnsview) still reads; CGNS 4 reads it too. So
        # MIXED sections carry no ElementStartOffset (a CGNS 4 node): readers scan the type codes.
        new_node(h5, "CGNSLibraryVersion", "CGNSLibraryVersion_t", "R4", np.array([3.4], dtype=np.float32))
        base = new_node(h5, "Base", "CGNSBase_t", "I4", np.array([cell_dim, phys], dtype=np.int32))
        zone = new_node(base, "Zone", "Zone_t", itype, np.array([[n], [mesh.n_cells], [0]], dtype=idt))
        new_node(zone, "ZoneType", "ZoneType_t", "C1", char_array("Unstructured"))
        grid = new_node(zone, "GridCoordinates", "GridCoordinates_t")
        for a, name in enumerate(["CoordinateX", "CoordinateY", "CoordinateZ"][:phys]):
            new_node(grid, name, "DataArray_t", "R8", np.ascontiguousarray(pts[:, a]))
        next_id = 1
        used_names = {"ZoneType", "GridCoordinates", "ZoneBC"}

        def unique(name: str) -> str:
            out, k = name, 1
            while out in used_names:
                k += 1
                out = f"{name[:28]}_{k}"
            return out

        def section(name: str, blocks: list[CellBlock]) -> tuple[int, int]:
            nonlocal next_id
            count = sum(len(b) for b in blocks)
            datas = [b.data[:, WEDGE_CGNS_TO_VTK] if b.type == "wedge" else b.data for b in blocks]
            if len(blocks) == 1:
                code = CGNS_CODE[blocks[0].type]
                conn = datas[0].ravel() + 1
            else:
                code = MIXED
                conn = np.concatenate([np.hstack([np.full((len(b), 1), CGNS_CODE[b.type]), d + 1]).ravel()
                                       for b, d in zip(blocks, datas, strict=True)])
            name = unique(name)
            sec = new_node(zone, name, "Elements_t", "I4", np.array([code, 0], dtype=np.int32))
            start, end = next_id, next_id + count - 1
            new_node(sec, "ElementRange", "IndexRange_t", itype, np.array([start, end], dtype=idt))
            new_node(sec, "ElementConnectivity", "DataArray_t", itype, conn.astype(idt))
            next_id = end + 1
            used_names.add(name)
            return start, end

        for b in mesh.cells:
            name = f"{b.type.capitalize()}Elements"
            section(name, [b])
        bcs = []
        for mname, blocks in mesh.markers.items():
            faces = [b for b in blocks if b.type != "vertex" and len(b)]
            verts = [b for b in blocks if b.type == "vertex"]
            if faces:
                start, end = section(mname, faces)
                bcs.append((mname, "FaceCenter" if cell_dim == 3 else "EdgeCenter",
                            np.arange(start, end + 1)))
            elif verts:
                ids = unique_ids(*[b.data for b in verts]) + 1
                bcs.append((mname, "Vertex", ids))
        if bcs:
            zbc = new_node(zone, "ZoneBC", "ZoneBC_t")
            for mname, loc, ids in bcs:
                bc = new_node(zbc, mname, "BC_t", "C1", char_array("UserDefined"))
                new_node(bc, "GridLocation", "GridLocation_t", "C1", char_array(loc))
                new_node(bc, "PointList", "IndexArray_t", itype, ids.astype(idt)[:, None])
