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
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.io.inputs import check_mesh_path, polymesh_folder_of
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.mesh.polyhedra import Polyhedra, counted_offsets, face_keys, from_counted, polyhedra_from_cells, problem

FILES = ("points", "faces", "owner", "neighbour", "boundary")
_HEADER = re.compile(rb"FoamFile\s*\{(?P<body>[^}]*)\}", re.S)
_ENTRY = re.compile(rb"(\w+)\s+(\"[^\"]*\"|[^;]*);")
_COUNT = re.compile(rb"\s*(\d+)\s*([({])")
_PATCH = re.compile(rb"([^\s{}()]+)\s*\{([^{}]*)\}", re.S)
_ZONE = re.compile(rb"([^\s{}()]+)\s*\{", re.S)
_COMMENT = re.compile(rb"//[^\n]*|/\*.*?\*/", re.S)


def poly_mesh_folder(path: str | Path) -> Path:
    """The polyMesh folder of a case folder or a polyMesh folder; InputError if neither."""
    p = check_mesh_path(path)
    folder = polymesh_folder_of(p)
    if folder is None:                            # not a folder (check_mesh_path passed a file)
        raise InputError("expected an OpenFOAM case folder (or its constant/polyMesh)", path=p)
    return folder


def _find(folder: Path, name: str) -> Path | None:
    for cand in (folder / name, folder / f"{name}.gz"):
        if cand.is_file():
            return cand
    return None


# ----------------------------------------------------------------------------------------------
# One FoamFile: header and lists
# ----------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class FoamHeader:
    """What the ``FoamFile`` dictionary of a file says: ``format`` (ascii/binary), the label and
    scalar sizes in bytes (from ``arch``), ``cls`` (class), ``note``, and where the data starts."""

    format: str
    label: int
    scalar: int
    cls: str
    note: str
    end: int


@dataclass(frozen=True, eq=False)
class FoamFile:
    """One file of the polyMesh as read: its path, whether gzip-compressed, the (uncompressed)
    bytes and the header."""

    path: Path
    compressed: bool
    data: bytes
    header: FoamHeader

    def error(self, message: str, pos: int | None = None, hint: str | None = None) -> InputError:
        """InputError naming this file and, for ASCII, the line of byte ``pos``."""
        line = None
        if pos is not None and self.header.format == "ascii":
            line = self.data.count(b"\n", 0, pos) + 1
        return InputError(message, path=self.path, line=line, hint=hint)


def read_foam_file(folder: Path, name: str) -> FoamFile:
    """Read ``folder/name`` (or ``name.gz``) and its header; InputError if missing or malformed."""
    path = _find(folder, name)
    if path is None:
        raise InputError(f"missing polyMesh file {name!r} (nor {name}.gz)", path=folder / name,
                         hint="an OpenFOAM polyMesh needs points, faces, owner, neighbour and boundary")
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise InputError(f"cannot read the file: {e.strerror}", path=path) from None
    compressed = raw[:2] == b"\x1f\x8b"
    if compressed:
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, gzip.BadGzipFile) as e:
            raise InputError(f"the gzip-compressed file is damaged or truncated ({e})", path=path) from None
    return FoamFile(path, compressed, raw, _header(raw, path))


def _header(data: bytes, path: Path) -> FoamHeader:
    m = _HEADER.search(data, 0, 1 << 16)
    if m is None:
        raise InputError("no FoamFile header: not an OpenFOAM file, or empty", path=path, line=1)
    body = _COMMENT.sub(b"", m["body"])
    entries = {k.decode(): v.strip().strip(b'"').decode("latin-1") for k, v in _ENTRY.findall(body)}
    fmt = entries.get("format", "ascii")
    if fmt not in ("ascii", "binary"):
        raise InputError(f"format {fmt!r} in the header; expected ascii or binary", path=path,
                         line=data.count(b"\n", 0, m.start()) + 1)
    arch = entries.get("arch", "")
    sizes = dict(re.findall(r"(label|scalar)=(\d+)", arch))
    label, scalar = int(sizes.get("label", 32)), int(sizes.get("scalar", 64))
    if label not in (32, 64) or scalar not in (32, 64):
        raise InputError(f"arch {arch!r}: label and scalar sizes must be 32 or 64", path=path,
                         line=data.count(b"\n", 0, m.start()) + 1)
    if "MSB" in arch:
        raise InputError("big-endian (MSB) binary files are not supported", path=path)
    return FoamHeader(fmt, label // 8, scalar // 8, entries.get("class", ""), entries.get("note", ""), m.end())


def _skip(data: bytes, pos: int) -> int:
    """Position of the next byte that is neither blank nor in a comment."""
    n = len(data)
    while pos < n:
        c = data[pos:pos + 2]
        if data[pos] <= 32:
            pos += 1
        elif c == b"//":
            end = data.find(b"\n", pos)
            pos = n if end < 0 else end + 1
        elif c == b"/*":
            end = data.find(b"*/", pos + 2)
            pos = n if end < 0 else end + 2
        else:
            break
    return pos


def _list_head(ff: FoamFile, pos: int, what: str) -> tuple[int, int, bytes]:
    """``(count, position after the opening bracket, bracket)`` of the list at ``pos``."""
    pos = _skip(ff.data, pos)
    m = _COUNT.match(ff.data, pos)
    if m is None:
        snippet = ff.data[pos:pos + 30].decode("latin-1", "replace").split("\n")[0]
        raise ff.error(f"expected the {what} list (a count, then '('), found {snippet!r}"
                       if pos < len(ff.data) else f"the file ends before the {what} list (truncated?)", pos)
    return int(m[1]), m.end(), m[2]


def _ascii_end(ff: FoamFile, start: int, what: str) -> int:
    """Position of the ``)`` closing the ASCII list whose ``(`` is at ``start - 1``."""
    arr = np.frombuffer(ff.data, dtype=np.uint8, offset=start)
    idx = np.flatnonzero((arr == 40) | (arr == 41))
    depth = np.cumsum(np.where(arr[idx] == 40, 1, -1), dtype=np.int64)
    close = np.flatnonzero(depth < 0)
    if not len(close):
        raise ff.error(f"the {what} list is not closed: the file is truncated", len(ff.data))
    return start + int(idx[close[0]])


def read_list(ff: FoamFile, pos: int, kind: str, what: str, width: int = 1) -> tuple[np.ndarray, int]:
    """The list at ``pos``: ``kind`` "label" (int64 (n,)) or "scalar" (float64 (n, width), the
    entries of a vector list), and the position after it. InputError naming the file, the line
    (ASCII) or the entry (binary) when the list is malformed, truncated, or not of its header's size."""
    n, start, bracket = _list_head(ff, pos, what)
    h = ff.header
    if bracket == b"{":                           # a uniform list: n{value}
        end = ff.data.find(b"}", start)
        if end < 0:
            raise ff.error(f"the uniform {what} list is not closed", start)
        value = np.fromstring(ff.data[start:end].translate(_NO_BRACKETS).decode("latin-1"), sep=" ")
        arr = np.tile(value, (n, 1)) if width > 1 else np.full(n, value[0] if len(value) else 0)
        return (arr.astype(np.int64) if kind == "label" else arr), end + 1
    size = h.label if kind == "label" else h.scalar
    if h.format == "binary":
        nbytes = n * width * size
        dtype = np.dtype(f"<{'i' if kind == 'label' else 'f'}{size}")
        if start + nbytes > len(ff.data):
            raise ff.error(f"{what}: the list declares {n} entries of {width * size} bytes ({h.label * 8}-bit "
                           f"labels, {h.scalar * 8}-bit scalars by the header's arch), {nbytes} bytes, but the "
                           f"file has {len(ff.data) - start} bytes after its '(': truncated, or the header's "
                           "arch is wrong")
        if ff.data[start + nbytes:start + nbytes + 1] != b")":
            raise ff.error(f"{what}: the list of {n} entries does not end where the header's arch "
                           f"(label={h.label * 8}, scalar={h.scalar * 8}) puts its end (entry {n}: no ')'); "
                           "is the arch entry right?")
        arr = np.frombuffer(ff.data, dtype=dtype, count=n * width, offset=start)
        arr = arr.astype(np.int64 if kind == "label" else np.float64)
        return (arr.reshape(n, width) if width > 1 else arr), start + nbytes + 1
    end = _ascii_end(ff, start, what)
    text = ff.data[start:end].translate(_NO_BRACKETS)
    arr = _numbers(ff, text, start, np.int64 if kind == "label" else np.float64, what)
    if len(arr) != n * width:
        raise ff.error(f"{what}: the list declares {n} entries but holds {len(arr) / width:g}", start)
    return (arr.reshape(n, width) if width > 1 else arr), end + 1


_NO_BRACKETS = bytes.maketrans(b"()", b"  ")


def _numbers(ff: FoamFile, text: bytes, start: int, dtype, what: str) -> np.ndarray:
    """The numbers of ``text`` (one ``np.fromstring``); a token that is not one is named with its line."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        try:
            arr = np.fromstring(text.decode("latin-1"), dtype=dtype, sep=" ")
            ok = len(arr) == len(text.split())
        except (ValueError, DeprecationWarning):
            ok = False
    if ok:
        return arr
    for m in re.finditer(rb"\S+", text):          # the error path only: find the bad token
        tok = m.group().decode("latin-1")
        try:
            int(tok) if dtype == np.int64 else float(tok)
        except ValueError:
            raise ff.error(f"{what}: {tok!r} is not {'an integer' if dtype == np.int64 else 'a number'}",
                           start + m.start()) from None
    raise ff.error(f"{what}: a number could not be read", start)


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
    n, start, _ = _list_head(ff, ff.header.end, "points")
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
    n, start, bracket = _list_head(ff, ff.header.end, "faces")
    if bracket != b"(":
        raise ff.error("faces: a uniform list cannot hold faces", start)
    end = _ascii_end(ff, start, "faces")
    tokens = _numbers(ff, ff.data[start:end].translate(_NO_BRACKETS), start, np.int64, "faces")
    try:
        starts = counted_offsets(tokens, n)
    except ValueError as e:
        raise ff.error(f"faces: the list declares {n} faces of the form n(p1 .. pn), but {e}", start) from None
    return from_counted(tokens, starts)


def _check_note(ff: FoamFile, n_points: int, n_cells: int, n_faces: int, n_internal: int) -> None:
    """The owner header's ``note "nPoints:.. nCells:.. nFaces:.. nInternalFaces:.."`` must agree."""
    said = dict(re.findall(r"(nPoints|nCells|nFaces|nInternalFaces)\s*:\s*(\d+)", ff.header.note))
    have = {"nPoints": n_points, "nCells": n_cells, "nFaces": n_faces, "nInternalFaces": n_internal}
    for key, value in said.items():
        if int(value) != have[key]:
            raise ff.error(f"the header's note says {key}:{value}, the mesh has {have[key]} (the files do not "
                           "belong together, or one is truncated)", ff.data.find(b"note"))


def _boundary(ff: FoamFile, n_faces: int, n_internal: int) -> tuple[Patch, ...]:
    n, start, _ = _list_head(ff, ff.header.end, "boundary")
    body = _COMMENT.sub(b"", ff.data[start:])
    patches, expect = [], n_internal
    for m in _PATCH.finditer(body):
        entries = {k.decode(): v.strip().decode("latin-1") for k, v in _ENTRY.findall(m[2])}
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
    if _find(folder, kind) is None:
        return []
    ff = read_foam_file(folder, kind)
    try:
        _, start, _ = _list_head(ff, ff.header.end, kind)
    except InputError:
        return []
    # zone dictionaries hold label lists (binary in binary files): names are the words before '{'
    # at depth 0 of the list; read them from the text between the zones only
    names, pos, data = [], start, ff.data
    while True:
        pos = _skip(data, pos)
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
    format and scalar size, gzip-compressed when the input was."""
    ff = src.points_file
    a, b = src.points_at
    if points.shape == src.points.shape and np.array_equal(points.view(np.int64), src.points.view(np.int64)):
        body = ff.data                            # unchanged: the input's bytes
    else:
        if ff.header.format == "binary":
            new = points.astype(f"<f{ff.header.scalar}").tobytes()
        else:
            digits = 17 if ff.header.scalar == 8 else 9
            fmt = f"(%.{digits}g %.{digits}g %.{digits}g)\n"
            new = b"\n" + (fmt * len(points) % tuple(points.ravel().tolist())).encode("ascii")
        body = ff.data[:a] + new + ff.data[b:]
    if ff.compressed:
        return gzip.compress(body, compresslevel=6, mtime=0)
    return body


# ----------------------------------------------------------------------------------------------
# A new case from a mesh of cell blocks (tests, benchmarks, conversions)
# ----------------------------------------------------------------------------------------------

_BANNER = b"""/*--------------------------------*- C++ -*----------------------------------*\\
  written by ffd
\\*---------------------------------------------------------------------------*/
"""


def polymesh_of(mesh: Mesh, *, wall: tuple[str, ...] = ()) -> tuple[Polyhedra, tuple[Patch, ...]]:
    """The polyMesh of a mesh of cell blocks: the faces in OpenFOAM's order (internal faces
    upper-triangular, then one patch per marker in order, then ``defaultFaces`` for boundary faces
    on no marker). Patches named in ``wall`` get type ``wall``, the others ``patch``."""
    poly, keys = polyhedra_from_cells([b for b in mesh.cells if b.type in ("tetra", "pyramid", "wedge",
                                                                            "hexahedron")])
    n_int = int(np.count_nonzero(poly.neighbour >= 0))
    patch_of = np.full(len(keys), len(mesh.markers), dtype=np.int64)
    for i, (name, blocks) in enumerate(mesh.markers.items()):
        for b in blocks:
            if b.type not in ("triangle", "quad"):
                continue
            k = face_keys(b.data)
            pos = _find_rows(keys, k)
            if (pos < 0).any():
                raise InputError(f"marker {name!r} has faces that are not boundary faces of the cells")
            patch_of[pos] = i
    order = np.argsort(patch_of, kind="stable")
    faces = n_int + order
    size = np.diff(poly.face_offsets)
    new_faces = np.concatenate([np.arange(n_int), faces])
    offsets = np.zeros(poly.n_faces + 1, dtype=np.int64)
    np.cumsum(size[new_faces], out=offsets[1:])
    gather = np.repeat(poly.face_offsets[new_faces] - offsets[:-1], size[new_faces]) + np.arange(offsets[-1])
    out = Polyhedra(poly.face_nodes[gather], offsets, poly.owner[new_faces], poly.neighbour[new_faces], poly.n_cells)
    names = list(mesh.markers) + ["defaultFaces"]
    counts = np.bincount(patch_of, minlength=len(names))
    patches, start = [], n_int
    for i, name in enumerate(names):
        if counts[i] or i < len(mesh.markers):
            kind = "wall" if name in wall else "patch"
            patches.append(Patch(name, kind, int(counts[i]), start))
        start += int(counts[i])
    return out, tuple(patches)


def _find_rows(table: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Row of each of ``keys`` (n, 4) in ``table`` (m, 4), -1 when absent (rows compared whole)."""
    void = np.dtype((np.void, 4 * 8))
    a = np.ascontiguousarray(table, dtype=np.int64).view(void).ravel()
    b = np.ascontiguousarray(keys, dtype=np.int64).view(void).ravel()
    order = np.argsort(a, kind="stable")
    if not len(a):
        return np.full(len(b), -1, dtype=np.int64)
    pos = np.minimum(np.searchsorted(a[order], b), len(a) - 1)
    return np.where(a[order][pos] == b, order[pos], -1)


def write_case(folder: str | Path, points: np.ndarray, poly: Polyhedra, patches, *, binary: bool = False,
               compress: bool = False, label: int = 32, scalar: int = 64) -> Path:
    """Write a polyMesh (``folder/constant/polyMesh``) and a minimal ``system/controlDict``: points,
    faces (faceList in ASCII, faceCompactList in binary), owner, neighbour, boundary, in the given
    format, compression and label/scalar sizes. Returns the case folder."""
    case = Path(folder)
    pm = case / "constant" / "polyMesh"
    pm.mkdir(parents=True, exist_ok=True)
    (case / "system").mkdir(exist_ok=True)
    fmt = "binary" if binary else "ascii"
    arch = f"LSB;label={label};scalar={scalar}"
    n_int = int(np.count_nonzero(poly.neighbour >= 0))
    note = f"nPoints:{len(points)} nCells:{poly.n_cells} nFaces:{poly.n_faces} nInternalFaces:{n_int}"
    ldt, sdt = f"<i{label // 8}", f"<f{scalar // 8}"

    def header(cls, obj, extra=""):
        return _BANNER + (f"FoamFile\n{{\n    version     2.0;\n    format      {fmt};\n    arch        \"{arch}\";\n"
                f"    class       {cls};\n    location    \"constant/polyMesh\";\n{extra}    object      {obj};\n}}\n"
                "// * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * //\n\n").encode()

    def labels(arr):
        arr = np.asarray(arr, dtype=np.int64)
        if binary:
            return f"{len(arr)}\n(".encode() + arr.astype(ldt).tobytes() + b")\n"
        return f"{len(arr)}\n(\n".encode() + ("%d\n" * len(arr) % tuple(arr.tolist())).encode() + b")\n"

    def put(name, data):
        p = pm / (name + (".gz" if compress else ""))
        p.write_bytes(gzip.compress(data, mtime=0) if compress else data)

    pts = np.asarray(points, dtype=np.float64)
    if binary:
        body = f"{len(pts)}\n(".encode() + pts.astype(sdt).tobytes() + b")\n"
    else:
        rows = "(%.17g %.17g %.17g)\n" * len(pts) % tuple(pts.ravel().tolist())
        body = f"{len(pts)}\n(\n".encode() + rows.encode() + b")\n"
    put("points", header("vectorField", "points") + body)
    if binary:
        put("faces", header("faceCompactList", "faces") + labels(poly.face_offsets) + labels(poly.face_nodes))
    else:
        size = np.diff(poly.face_offsets)
        fmt_of = {int(k): f"{k}(" + " ".join(["%d"] * int(k)) + ")\n" for k in np.unique(size)}
        rows = "".join([fmt_of[k] for k in size.tolist()]) % tuple(poly.face_nodes.tolist())
        put("faces", header("faceList", "faces") + f"{poly.n_faces}\n(\n".encode() + rows.encode() + b")\n")
    note_line = f"    note        \"{note}\";\n"
    put("owner", header("labelList", "owner", note_line) + labels(poly.owner))
    put("neighbour", header("labelList", "neighbour", note_line) + labels(poly.neighbour[:n_int]))
    text = f"{len(patches)}\n(\n"
    for p in patches:
        text += f"    {p.name}\n    {{\n        type            {p.type};\n"
        if p.type == "wall":
            text += "        inGroups        List<word> 1(wall);\n"
        text += f"        nFaces          {p.n_faces};\n        startFace       {p.start};\n    }}\n"
    text += ")\n"
    (pm / "boundary").write_bytes(header("polyBoundaryMesh", "boundary") + text.encode())
    (case / "system" / "controlDict").write_text(_CONTROL_DICT)
    return case


_CONTROL_DICT = """FoamFile
{
    version     2.0;
    format      ascii;
    class       dictionary;
    object      controlDict;
}
application     potentialFoam;
startFrom       startTime;
startTime       0;
stopAt          endTime;
endTime         1;
deltaT          1;
writeControl    timeStep;
writeInterval   1;
writeFormat     ascii;
writePrecision  17;
writeCompression off;
timeFormat      general;
timePrecision   6;
runTimeModifiable false;
"""
