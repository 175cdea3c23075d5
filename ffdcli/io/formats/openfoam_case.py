"""A new OpenFOAM case from a mesh of cell blocks (tests, benchmarks, conversions).

:func:`polymesh_of` turns tetrahedra, pyramids, prisms and hexahedra with their markers into a
polyMesh in OpenFOAM's order (internal faces upper-triangular, then one patch per marker);
:func:`write_case` writes it (points, faces, owner, neighbour, boundary) in ASCII or binary, plain
or gzip-compressed, with any label and scalar size, and a minimal ``system/controlDict``.
"""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.io.formats.openfoam import Patch
from ffdcli.mesh import Mesh
from ffdcli.mesh.polyhedra import Polyhedra, face_keys, polyhedra_from_cells

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
