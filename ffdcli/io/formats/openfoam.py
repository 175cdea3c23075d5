"""OpenFOAM meshes: a case folder (or its ``constant/polyMesh``) read as a polyhedral mesh.

Reading takes ``points``, ``faces``, ``owner``, ``neighbour`` and ``boundary`` of the polyMesh, each
in ASCII or binary, plain or gzip-compressed (``points.gz``; the plain file wins when both exist, as
in OpenFOAM), with the label and scalar sizes of the header's ``arch`` entry
(``"LSB;label=32;scalar=64"``, OpenFOAM's default when there is none). Faces may be a ``faceList``
(``4(0 1 2 3)`` entries) or a ``faceCompactList`` (offsets, then the flat labels). Parsing is
vectorised: one ``np.frombuffer`` (binary) or ``np.fromstring`` (ASCII) per list, list ends found by
counting brackets with array operations, the counted face records by one compiled pass.

The :class:`~ffdcli.mesh.Mesh` returned has ``polyhedra`` (:class:`~ffdcli.polyhedra.Polyhedra`, the
polyMesh's faces, owner and neighbour as they are) and no cell blocks; its markers are the patches
(``boundary``), in file order, their faces as triangles and quadrilaterals (larger polygons split
into triangle fans about their first node). ``source`` (:class:`FoamSource`) keeps the patches with
their types and groups, the names of the ``cellZones``/``faceZones``/``pointZones`` and everything
the writer needs.

Writing (only to an OpenFOAM case, only from an OpenFOAM case) copies the input: the case folder
(or the polyMesh folder when that was given) into the output folder, every file byte for byte
except ``points``, which is written in the input's format (ASCII or binary), scalar size,
compression and header. Left out of the copy: ``processor*`` folders (a decomposition of the old
mesh) and time folders other than ``0`` (fields of the old mesh's cells). ASCII points are written
with 17 significant digits (9 for scalar=32), so that reading the file back gives the coordinates ffd
computed; points unchanged to the last bit are the input's bytes (a zero design gives the input
back byte for byte).
"""

from __future__ import annotations

import gzip
import os
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.io.formats.common import FOLDER_FORMAT, MESH_FORMATS, MeshFormat
from ffdcli.io.formats.foamfile import (
    COMMENT,
    ENTRY,
    FoamFile,
    ascii_end,
    find,
    labels,
    list_head,
    read_foam_file,
    read_list,
    skip_blank,
)
from ffdcli.io.inputs import check_mesh_path, polymesh_folder_of
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.mesh.polyhedra import Polyhedra, problem, split_counted

FILES = ("points", "faces", "owner", "neighbour", "boundary")
_PATCH = re.compile(rb"([^\s{}()]+)\s*\{([^{}]*)\}", re.S)
_ZONE = re.compile(rb"([^\s{}()]+)\s*\{", re.S)


def poly_mesh_folder(path: str | Path) -> Path:
    """The polyMesh folder of a case folder or a polyMesh folder; InputError if neither."""
    p = check_mesh_path(path)
    folder = polymesh_folder_of(p)
    if folder is None:                            # not a folder (check_mesh_path passed a file)
        raise InputError("expected an OpenFOAM case folder (or its constant/polyMesh)", path=p)
    return folder


# ----------------------------------------------------------------------------------------------
# The polyMesh
# ----------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Patch:
    """One patch of ``boundary``: name, type (patch, wall, empty, symmetryPlane, cyclic, ...),
    groups (``inGroups``), its faces ``start .. start + n_faces - 1``."""

    name: str
    type: str
    n_faces: int
    start: int
    groups: tuple[str, ...] = ()


@dataclass(eq=False)
class FoamSource:
    """What the writer needs: the folder copied (``root``: the case, or the polyMesh folder when
    that was given), the polyMesh folder relative to it, the points file as read (path, header,
    compression, the bytes around the list), the input points, the patches and zone names."""

    root: Path
    poly_mesh: Path
    points_file: FoamFile
    points_at: tuple[int, int]          #: byte range of the point list's entries in the data
    points: np.ndarray
    patches: tuple[Patch, ...]
    zones: dict[str, list[str]] = field(default_factory=dict)


def read(path: str | Path, progress=None) -> Mesh:
    """Read an OpenFOAM case folder or polyMesh folder (see the module docstring)."""
    root = Path(path)
    folder = poly_mesh_folder(root)
    pts_file = read_foam_file(folder, "points")
    points, points_at = _points(pts_file)
    faces_file = read_foam_file(folder, "faces")
    nodes, offsets = _faces(faces_file)
    owner_file = read_foam_file(folder, "owner")
    owner, _ = read_list(owner_file, owner_file.header.end, "label", "owner")
    nei_file = read_foam_file(folder, "neighbour")
    nei, _ = read_list(nei_file, nei_file.header.end, "label", "neighbour")
    n_faces = len(offsets) - 1
    if len(owner) != n_faces:
        raise owner_file.error(f"owner has {len(owner)} entries, faces has {n_faces} faces: one owner per face "
                               "expected (the two files do not belong together)")
    if len(nei) > n_faces:
        raise nei_file.error(f"neighbour has {len(nei)} entries, more than the {n_faces} faces")
    n_cells = int(max(owner.max(initial=-1), nei.max(initial=-1))) + 1
    _check_note(owner_file, len(points), n_cells, n_faces, len(nei))
    neighbour = np.full(n_faces, -1, dtype=np.int64)
    neighbour[:len(nei)] = nei
    poly = Polyhedra(nodes, offsets, owner, neighbour, n_cells)
    bad = problem(poly, len(points))
    if bad is not None:
        which, message, index = bad
        ff = {"faces": faces_file, "owner": owner_file, "neighbour": nei_file}[which]
        raise ff.error(f"{message} (entry {index})")
    patches = _boundary(read_foam_file(folder, "boundary"), n_faces, len(nei))
    markers = {}
    for p in patches:
        blocks = poly.boundary_faces(np.arange(p.start, p.start + p.n_faces))
        markers[p.name] = [CellBlock(t, blocks[t]) for t in ("triangle", "quad") if t in blocks]
    zones = {kind: _zone_names(folder, kind) for kind in ("cellZones", "faceZones", "pointZones")}
    source = FoamSource(root=root, poly_mesh=folder.relative_to(root), points_file=pts_file, points_at=points_at,
                        points=points, patches=patches, zones={k: v for k, v in zones.items() if v})
    return Mesh(points=points, dim=3, markers=markers, path=root, format="openfoam", source=source,
                polyhedra=poly)


def _points(ff: FoamFile) -> tuple[np.ndarray, tuple[int, int]]:
    n, start, _ = list_head(ff, ff.header.end, "points")
    pts, end = read_list(ff, ff.header.end, "scalar", "points", width=3)
    return pts, (start, end - 1)


def _faces(ff: FoamFile) -> tuple[np.ndarray, np.ndarray]:
    """The faces as flat nodes and offsets (faceList or faceCompactList)."""
    compact = ff.header.cls == "faceCompactList" or ff.header.format == "binary"
    if compact:
        offsets, end = read_list(ff, ff.header.end, "label", "faces (offsets)")
        nodes, _ = read_list(ff, end, "label", "faces (point labels)")
        if len(offsets) == 0:
            offsets = np.zeros(1, dtype=np.int64)
        sizes = np.diff(offsets)
        if offsets[0] != 0 or (sizes < 0).any() or offsets[-1] != len(nodes):
            bad = int(np.flatnonzero(sizes < 0)[0]) if (sizes < 0).any() else len(sizes)
            raise ff.error(f"faces: the offsets do not match the {len(nodes)} point labels (entry {bad})")
        return nodes, offsets
    n, start, bracket = list_head(ff, ff.header.end, "faces")
    if bracket != b"(":
        raise ff.error("faces: a uniform list cannot hold faces", start)
    end = ascii_end(ff, start, "faces")
    tokens = labels(ff, start, end, "faces")
    try:
        return split_counted(tokens, n)
    except ValueError as e:
        raise ff.error(f"faces: the list declares {n} faces of the form n(p1 .. pn), but {e}", start) from None


def _check_note(ff: FoamFile, n_points: int, n_cells: int, n_faces: int, n_internal: int) -> None:
    """The owner header's ``note "nPoints:.. nCells:.. nFaces:.. nInternalFaces:.."`` must agree."""
    said = dict(re.findall(r"(nPoints|nCells|nFaces|nInternalFaces)\s*:\s*(\d+)", ff.header.note))
    have = {"nPoints": n_points, "nCells": n_cells, "nFaces": n_faces, "nInternalFaces": n_internal}
    for key, value in said.items():
        if int(value) != have[key]:
            raise ff.error(f"the header's note says {key}:{value}, the mesh has {have[key]} (the files do not "
                           "belong together, or one is truncated)", ff.data.find(b"note"))


def _boundary(ff: FoamFile, n_faces: int, n_internal: int) -> tuple[Patch, ...]:
    n, start, _ = list_head(ff, ff.header.end, "boundary")
    body = COMMENT.sub(b"", ff.data[start:])
    patches, expect = [], n_internal
    for m in _PATCH.finditer(body):
        entries = {k.decode(): v.strip().decode("latin-1") for k, v in ENTRY.findall(m[2])}
        name = m[1].decode("latin-1")
        try:
            nf, sf = int(entries["nFaces"]), int(entries["startFace"])
        except (KeyError, ValueError):
            raise ff.error(f"patch {name!r} needs integer nFaces and startFace", start + m.start()) from None
        if sf != expect or nf < 0 or sf + nf > n_faces:
            raise ff.error(f"patch {name!r}: faces {sf} to {sf + nf - 1}, expected to start at face {expect} "
                           f"and end by face {n_faces - 1} (internal faces first, then the patches in order)",
                           start + m.start())
        expect = sf + nf
        groups = tuple(re.findall(r"\w+", entries.get("inGroups", "").partition("(")[2]))
        patches.append(Patch(name, entries.get("type", "patch"), nf, sf, groups))
    if len(patches) != n:
        raise ff.error(f"the boundary list declares {n} patches, {len(patches)} were read", start)
    if expect != n_faces:
        raise ff.error(f"the patches end at face {expect}, the mesh has {n_faces} faces: boundary faces "
                       "without a patch", start)
    return tuple(patches)


def _zone_names(folder: Path, kind: str) -> list[str]:
    """The names of the zones in ``cellZones``/``faceZones``/``pointZones`` (kept as they are)."""
    if find(folder, kind) is None:
        return []
    ff = read_foam_file(folder, kind)
    try:
        _, start, _ = list_head(ff, ff.header.end, kind)
    except InputError:
        return []
    # zone dictionaries hold label lists (binary in binary files): names are the words before '{'
    # at depth 0 of the list; read them from the text between the zones only
    names, pos, data = [], start, ff.data
    while True:
        pos = skip_blank(data, pos)
        m = _ZONE.match(data, pos)
        if m is None:
            break
        names.append(m[1].decode("latin-1"))
        close = _dict_end(data, m.end())
        if close < 0:
            break
        pos = close + 1
    return names


def _dict_end(data: bytes, pos: int) -> int:
    """The ``}`` closing the dictionary opened before ``pos``, skipping binary lists of labels."""
    depth = 1
    while depth:
        m = re.compile(rb"[{}]|(\d+)\s*\(").search(data, pos)
        if m is None:
            return -1
        if m[1] is not None:                      # a list: skip it whole (ASCII or binary)
            close = data.find(b")", m.end())
            pos = m.end() if close < 0 else close + 1
            continue
        depth += 1 if m.group() == b"{" else -1
        pos = m.end()
    return pos - 1


# ----------------------------------------------------------------------------------------------
# Writing: a copy of the case with new points
# ----------------------------------------------------------------------------------------------

_TIME = re.compile(r"[-+]?\d+(\.\d*)?([eE][-+]?\d+)?")


def write(mesh: Mesh, path: str | Path, points: np.ndarray, progress=None) -> None:
    """Write the deformed case to the folder ``path`` (which must not exist: the output plan
    writes to a fresh temporary folder and renames it). See the module docstring."""
    src = mesh.source
    if mesh.format != "openfoam" or not isinstance(src, FoamSource):
        raise InputError("an OpenFOAM case is written only as a copy of an OpenFOAM input case; "
                         f"this mesh was read from {mesh.format or 'memory'}: give the output the input's "
                         "format", path=path)
    out = Path(path)
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape != src.points.shape:
        raise ValueError(f"points {pts.shape} do not match the mesh {src.points.shape}")
    if out.exists() and not out.is_dir():
        out.unlink()                              # the plan's empty temporary file: a folder goes there
    out.mkdir(exist_ok=True)
    _copy_tree(src.root, out, top=True, skip=out.resolve().parent)
    if not np.array_equal(pts.view(np.int64), src.points.view(np.int64)):     # unchanged: the copy is the input
        target = out / src.poly_mesh / src.points_file.path.name
        target.write_bytes(points_bytes(src, pts))


def _copy_tree(src: Path, dest: Path, top: bool = False, skip: Path | None = None) -> None:
    """Copy the folder ``src`` into ``dest`` (symlinks as links), leaving out, at the top, processor
    and non-zero time folders, and anywhere the folder ``skip`` (where the output is written, when
    it is inside the case) and its ancestors' entries that hold it."""
    if not src.is_dir():
        raise InputError("the input case folder is gone; cannot copy it to write the output", path=src)
    for entry in sorted(os.scandir(src), key=lambda e: e.name):
        if top and entry.is_dir() and (entry.name.startswith("processor")
                                       or (_TIME.fullmatch(entry.name) and float(entry.name) != 0.0)):
            continue
        if skip is not None and entry.is_dir(follow_symlinks=False):
            here = Path(entry.path).resolve()
            if here == skip or here in skip.parents:
                continue                          # the output's folder (e.g. case/out): not copied into itself
        target = dest / entry.name
        if entry.is_symlink():
            os.symlink(os.readlink(entry.path), target)
        elif entry.is_dir():
            target.mkdir()
            _copy_tree(Path(entry.path), target, skip=skip)
        else:
            shutil.copy2(entry.path, target)


def points_bytes(src: FoamSource, points: np.ndarray) -> bytes:
    """The bytes of the new points file: the input's header and framing, the new coordinates in its
    format and scalar size, gzip-compressed when the input was (a writer whose points did not move
    keeps the input's file as it is)."""
    ff = src.points_file
    a, b = src.points_at
    if ff.header.format == "binary":
        new = np.ascontiguousarray(points, dtype=f"<f{ff.header.scalar}").tobytes()
    else:
        digits = 17 if ff.header.scalar == 8 else 9
        fmt = f"(%.{digits}g %.{digits}g %.{digits}g)\n"
        new = b"\n" + (fmt * len(points) % tuple(points.ravel().tolist())).encode("ascii")
    body = ff.data[:a] + new + ff.data[b:]
    if ff.compressed:
        return gzip.compress(body, compresslevel=6, mtime=0)
    return body


MESH_FORMATS.register(MeshFormat(FOLDER_FORMAT, (), "an OpenFOAM case", read, write))
