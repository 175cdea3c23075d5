"""VTK meshes: XML ``.vtu`` and legacy ``.vtk`` unstructured grids, through meshio.

Convention for markers (what :func:`write` produces and :func:`read` recovers):

* Interior cells and boundary cells are all cells of the one unstructured grid: first the interior
  cells, then the cells of each marker in marker order (VTK node order, as in :class:`Mesh`).
* The integer cell-data array ``ffd_marker`` (Int32) holds, per cell, 0 for an interior cell and
  ``k`` (1, 2, ...) for a cell of the k-th marker.
* The marker names are field data of the grid: one Int32 array per marker, named by the marker
  name, holding two values ``[k, dim]`` (its id in ``ffd_marker`` and the topological dimension of
  its cells). This is meshio's ``field_data`` convention (the one its Gmsh reader uses), so names
  keep spaces and any characters; ParaView shows them as field data. In legacy files array names
  are written with VTK's ``%XX`` escapes for blanks and ``%`` and unescaped on read.

A file without ``ffd_marker`` (a plain VTU from another tool) gives a :class:`Mesh` with no markers
whose interior cells are the cells of the highest topological dimension; lower-dimensional cells are
dropped. A ``gmsh:physical`` cell-data array with named field data (meshio's Gmsh convention) is
accepted in place of ``ffd_marker``. Ids present in ``ffd_marker`` without a name become markers
named ``marker<k>``.

meshio writes no field data, so the writer adds it: for ``.vtu`` a ``<FieldData>`` element is
inserted before the ``<Piece>``; for legacy ``.vtk`` (ASCII, version 4.2: VTK 9 cannot read the
int arrays of meshio's default 5.1 format) a ``FIELD FieldData`` block follows the ``DATASET`` line.
meshio's legacy reader ignores that block, so :func:`read` parses it from the file header itself.
meshio failures (including its ``sys.exit``) and its warnings on stderr become one
:class:`InputError` naming the file.
"""

from __future__ import annotations

import contextlib
import io
import logging
import re
import sys
import warnings
from pathlib import Path

import numpy as np

from ffdcli.deferred import deferred
from ffdcli.errors import InputError
from ffdcli.io.atomic import atomic_path
from ffdcli.io.formats.common import MESH_FORMATS, MeshFormat
from ffdcli.io.formats.vtk_check import problem as file_problem
from ffdcli.io.room import diagnosed
from ffdcli.mesh import CELL_DIM, CellBlock, Mesh
from ffdcli.progress import no_progress

saxutils = deferred("xml.sax.saxutils")   # 20 ms (it imports urllib and ssl): for the VTU writer
meshio = deferred("meshio")     # 0.1 s with its xml imports: imported when a VTK mesh is read or written

#: Cell-data array with the marker id of each cell (0 = interior).
MARKER_ARRAY = "ffd_marker"
_GMSH_ARRAY = "gmsh:physical"


#: What a file of each format is expected to be, in messages.
_KIND = {"vtu": "a VTK XML unstructured grid (.vtu)", "vtk": "a legacy VTK unstructured grid (.vtk)"}


def _format(path: Path) -> str:
    return "vtu" if path.suffix.lower() == ".vtu" else "vtk"


@contextlib.contextmanager
def _quiet_meshio(path: Path, action: str):
    """Silence meshio's warnings and turn any of its failures into one InputError."""
    err = io.StringIO()
    try:
        with warnings.catch_warnings(), contextlib.redirect_stderr(err), \
                contextlib.redirect_stdout(io.StringIO()):
            warnings.simplefilter("ignore")
            logging.disable(logging.WARNING)
            try:
                yield
            finally:
                logging.disable(logging.NOTSET)
    except InputError:
        raise
    except OSError:
        if action == "write":                     # a full disk, a file-size limit: the output plan's words
            raise
        raise InputError(f"cannot read this {_format(path).upper()} file: {sys.exc_info()[1]}", path=path) from None
    except (Exception, SystemExit) as e:          # meshio calls sys.exit(1) on some bad files
        found = file_problem(path) if action == "read" else None
        if found is not None:                     # the first problem, on its line, in words
            line, text = found
            raise InputError(f"{text}; expected {_KIND[_format(path)]}", path=path, line=line) from None
        said = " ".join(err.getvalue().split()).removeprefix("Error: ")
        detail = said or (str(e) if not isinstance(e, SystemExit) else "")
        raise InputError(f"cannot {action} this {_format(path).upper()} file" + (f" ({detail[:200]})" if detail else "")
                         + (f"; expected {_KIND[_format(path)]}" if action == "read" else ""), path=path) from None


# ----------------------------------------------------------------------------------------------
# reading


def read(path: str | Path, progress=None) -> Mesh:
    """Read a ``.vtu`` or legacy ``.vtk`` unstructured grid into a :class:`Mesh`.

    Markers are recovered from the ``ffd_marker`` cell data and the names in field data (see the
    module docstring); points are (N, 3) float64; ``dim`` is the highest topological dimension of
    the interior cells (of all cells when the file has no marker array). Raises InputError naming
    the file when it is empty, not a VTK unstructured grid, or meshio cannot read it.
    """
    path = Path(path)
    progress = progress or no_progress
    try:
        size = path.stat().st_size
    except OSError as e:
        raise InputError(f"cannot open: {e.strerror or e}", path=path) from None
    if size == 0:
        raise InputError(f"the file is empty; expected a {_format(path).upper()} unstructured grid",
                         path=path)
    with progress(f"reading {path.name}", 1) as bar, _quiet_meshio(path, "read"):
        m = meshio.read(path, file_format="vtu" if _format(path) == "vtu" else "vtk")
        bar.update(1)
    points = np.asarray(m.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise InputError(f"expected points with 2 or 3 coordinates, got shape {points.shape}", path=path)
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    field = dict(m.field_data)
    if _format(path) == "vtk":
        field.update(_legacy_field_data(path))
    blocks = [(b.type, np.asarray(b.data, dtype=np.int64)) for b in m.cells]
    unknown = sorted({t for t, _ in blocks if t not in CELL_DIM})
    if unknown:
        raise InputError(f"cell type(s) {', '.join(unknown)} are not supported; expected "
                         f"{', '.join(CELL_DIM)}", path=path)
    for t, data in blocks:
        if len(data) and (data.min() < 0 or data.max() >= len(points)):
            raise InputError(f"{t} cells refer to point ids outside 0..{len(points) - 1}", path=path)

    array = MARKER_ARRAY if MARKER_ARRAY in m.cell_data else (
        _GMSH_ARRAY if _GMSH_ARRAY in m.cell_data and field else None)
    if array is None:
        dim = max((CELL_DIM[t] for t, d in blocks if len(d)), default=0)
        cells = _merge([(t, d) for t, d in blocks if CELL_DIM[t] == dim])
        return Mesh(points=points, dim=_mesh_dim(dim, points), cells=cells, markers={}, path=path,
                    format=_format(path))

    tags = [np.asarray(a).ravel().astype(np.int64) for a in m.cell_data[array]]
    names = _names_by_id(field, path)
    interior = [(t, d[tag == 0]) for (t, d), tag in zip(blocks, tags, strict=True)]
    dim = max((CELL_DIM[t] for t, d in interior if len(d)), default=0)
    ids = sorted(set(names) | {int(v) for tag in tags for v in np.unique(tag[tag > 0]).tolist()})
    markers: dict[str, list[CellBlock]] = {}
    for k in ids:
        name = names.get(k, f"marker{k}")
        markers[name] = _merge([(t, d[tag == k]) for (t, d), tag in zip(blocks, tags, strict=True)])
    return Mesh(points=points, dim=_mesh_dim(dim, points), cells=_merge(interior), markers=markers,
                path=path, format=_format(path))


def _mesh_dim(cell_dim: int, points: np.ndarray) -> int:
    if cell_dim in (2, 3):
        return cell_dim
    flat = len(points) == 0 or np.ptp(points[:, 2]) == 0
    return 2 if flat else 3


def _merge(parts) -> list[CellBlock]:
    """Cell blocks from (type, rows) pieces: empty pieces dropped, consecutive same types joined."""
    out: list[tuple[str, list[np.ndarray]]] = []
    for t, d in parts:
        if len(d) == 0:
            continue
        if out and out[-1][0] == t:
            out[-1][1].append(d)
        else:
            out.append((t, [d]))
    return [CellBlock(t, np.concatenate(ds)) for t, ds in out]


def _names_by_id(field: dict, path: Path) -> dict[int, str]:
    names: dict[int, str] = {}
    for name, value in field.items():
        v = np.asarray(value).ravel()
        if len(v) < 1 or not np.issubdtype(v.dtype, np.number):
            continue
        k = int(v[0])
        if k <= 0:
            continue
        if k in names:
            raise InputError(f"marker id {k} has two names in the field data: {names[k]!r} and "
                             f"{name!r}", path=path)
        names[k] = name
    return names


_FIELD_RE = re.compile(rb"^FIELD\s+\S+\s+(\d+)\s*$")


def _legacy_field_data(path: Path) -> dict[str, np.ndarray]:
    """Field data of a legacy file's DATASET (the block meshio skips): {name: int array}."""
    out: dict[str, np.ndarray] = {}
    with open(path, "rb") as fh:
        lines = iter(fh)
        for line in lines:
            s = line.strip()
            if s.startswith(b"POINTS") or s.startswith(b"CELLS"):
                break
            m = _FIELD_RE.match(s)
            if not m:
                continue
            for _ in range(int(m.group(1))):
                head = next(lines, b"").split()
                if len(head) != 4:
                    return out
                name, ncomp, ntup = head[0].decode("utf-8", "replace"), int(head[1]), int(head[2])
                vals: list[str] = []
                while len(vals) < ncomp * ntup:
                    nxt = next(lines, None)
                    if nxt is None:
                        return out
                    vals.extend(nxt.decode("ascii", "replace").split())
                try:
                    out[_unescape(name)] = np.array([int(float(v)) for v in vals])
                except ValueError:
                    continue
            break
    return out


def _escape(name: str) -> str:
    """VTK legacy array names: blanks and '%' as %XX (what VTK itself writes and reads)."""
    return "".join(f"%{ord(c):02X}" if c.isspace() or c == "%" or ord(c) < 33 else c for c in name)


def _unescape(name: str) -> str:
    return re.sub(r"%([0-9A-Fa-f]{2})", lambda m: chr(int(m.group(1), 16)), name)


# ----------------------------------------------------------------------------------------------
# writing


def write(mesh: Mesh, path: str | Path, points: np.ndarray, progress=None) -> None:
    """Write ``mesh`` with coordinates ``points`` (N, 3) as ``.vtu`` or legacy ``.vtk``, atomically.

    Interior cells, then each marker's cells, with the ``ffd_marker`` cell data and the marker
    names in field data (module docstring). Coordinates are stored as float64, so a VTU read back
    gives the same floats; the legacy ASCII writer prints 16 significant digits (meshio's choice),
    which round-trips to about 1e-16 relative, not always to the last bit.
    """
    path = Path(path)
    progress = progress or no_progress
    points = np.asarray(points, dtype=np.float64)
    if points.shape != mesh.points.shape:
        raise ValueError(f"points {points.shape} do not match the mesh {mesh.points.shape}")
    if not np.isfinite(points).all():
        raise ValueError("cannot write non-finite point coordinates (NaN or inf)")
    cells, tags = [], []
    for b in mesh.cells:
        cells.append((b.type, b.data))
        tags.append(np.zeros(len(b), dtype=np.int32))
    field = {}
    for k, (name, blocks) in enumerate(mesh.markers.items(), start=1):
        dim = max((CELL_DIM[b.type] for b in blocks), default=mesh.dim - 1)
        field[name] = np.array([k, dim], dtype=np.int32)
        for b in blocks:
            cells.append((b.type, b.data))
            tags.append(np.full(len(b), k, dtype=np.int32))
    m = meshio.Mesh(points, cells, cell_data={MARKER_ARRAY: tags} if cells else {})
    fmt = _format(path)
    with progress(f"writing {path.name}", 1) as bar, atomic_path(path) as tmp:
        try:
            with _quiet_meshio(path, "write"):
                if fmt == "vtu":
                    meshio.write(tmp, m, file_format="vtu")
                else:
                    meshio.write(tmp, m, file_format="vtk42", binary=False)
        except OSError as e:                      # NumPy's tofile says no errno: find why again
            raise diagnosed(e, tmp) from None
        if field:
            _add_field_data(tmp, field, fmt)
        bar.update(1)


def _add_field_data(tmp: Path, field: dict[str, np.ndarray], fmt: str) -> None:
    data = tmp.read_bytes()
    if fmt == "vtu":
        arrays = "".join(f'<DataArray type="Int32" Name={saxutils.quoteattr(name)} NumberOfTuples="1" '
                         f'NumberOfComponents="{len(v)}" format="ascii">'
                         f'{" ".join(str(int(x)) for x in v)}</DataArray>\n'
                         for name, v in field.items())
        block = f"<FieldData>\n{arrays}</FieldData>\n".encode()
        at = data.find(b"<Piece")
        if at < 0:
            raise RuntimeError("meshio wrote a VTU without <Piece>")
        data = data[:at] + block + data[at:]
    else:
        arrays = "".join(f"{_escape(name)} {len(v)} 1 int\n{' '.join(str(int(x)) for x in v)}\n"
                         for name, v in field.items())
        block = f"FIELD FieldData {len(field)}\n{arrays}".encode()
        m = re.search(rb"^DATASET[^\n]*\n", data, re.M)
        if m is None:
            raise RuntimeError("meshio wrote a legacy VTK file without DATASET")
        data = data[:m.end()] + block + data[m.end():]
    tmp.write_bytes(data)


MESH_FORMATS.register(MeshFormat("vtu", (".vtu",), "a VTK XML unstructured grid", read, write))
MESH_FORMATS.register(MeshFormat("vtk", (".vtk",), "a legacy VTK unstructured grid", read, write))
