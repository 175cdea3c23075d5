"""SU2's own FFD boxes appended to a ``.su2`` mesh: read them, and bring them up to date with a new surface.

SU2_DEF (``DV_KIND= FFD_SETTING``) appends an FFD section after the markers::

    FFD_NBOX= 1
    FFD_NLEVEL= 1
    FFD_TAG= MAIN_BOX
    FFD_LEVEL= 0
    FFD_DEGREE_I= 14          % per logical direction; no FFD_DEGREE_K in 2D
    FFD_DEGREE_J= 1
    FFD_BLENDING= BEZIER      % or BSPLINE_UNIFORM, then BSPLINE_ORDER_I/J(/K)= lines; absent in old files
    FFD_PARENTS= 0            % followed by that many tags
    FFD_CHILDREN= 0
    FFD_CORNER_POINTS= 4      % 8 in 3D; 2D files give the 4 corners of the lower face as "x y"
    ...
    FFD_CONTROL_POINTS= 60    % "i j k x y z" (in 2D z = -0.5 / +0.5)
    ...
    FFD_SURFACE_POINTS= 192   % "MARKER_TAG point_id u v w": parameters of the surface nodes in the box
    ...

``FFD_SURFACE_POINTS`` are the parametric coordinates of the surface as it was when SU2 embedded it.
SU2_DEF and SU2_DOT do not embed again: they evaluate the box at those parameters. A mesh that ffd
deformed but whose section still holds the *original* parameters is silently put back on the original
surface by the next SU2_DEF (measured: to 5e-16). So when ffd writes a deformed SU2 mesh it brings the
section up to date (:func:`refresh`): each listed surface node is embedded again, at its new position,
in the *same* box (control points unchanged), by Newton's method started from its old parameters. A
zero design change in SU2 then reproduces ffd's surface (to the inversion tolerance), and SU2's own FFD
design variables act on the deformed wing. A node that the design moved out of the box is left out of
the list, as SU2 itself leaves out nodes outside a box (SU2 will not move it); the summary counts them.

The box is a tensor-product Bernstein (Bezier) volume of degree ``FFD_DEGREE_*`` per direction, or a
uniform clamped B-spline of order ``BSPLINE_ORDER_*``; evaluation here is plain NumPy (any degree,
vectorised over points). Old files without ``FFD_BLENDING`` are Bezier; they are written back in the
current form (with ``FFD_BLENDING= BEZIER``), which SU2 8 reads. Nested boxes (parents/children) are
refreshed box by box like the others.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np

from ffdcli.errors import InputError
from ffdcli.lattice.spline import basis_derivs, clamped_knots
from ffdcli.mesh import diagonal

#: SU2's ``FFD_TOLERANCE`` default: parameters within it of [0, 1] belong to the box, and are clipped to
#: ``[tol, 1 - tol]`` as SU2 does when it embeds.
SU2_FFD_TOL = 1e-10
#: A node belongs to a box when Newton's residual is at most this fraction of the box's diagonal.
RESIDUAL_TOL = 1e-9
#: Newton iterations at most (it converges in a handful from the old parameters).
NEWTON_ITERATIONS = 50
#: Points evaluated at a time (bounds the temporary arrays: chunk x control points x 3 floats).
CHUNK = 16384

_KEY = re.compile(r"^\s*([A-Z][A-Z0-9_]*)\s*=\s*(.*?)\s*$")


@dataclass(frozen=True)
class Su2FfdBox:
    """One FFD box of an SU2 mesh file.

    Attributes
    ----------
    tag, level : str, int
    degree : tuple of int
        ``FFD_DEGREE_I/J(/K)`` as written (2 values in 2D, 3 in 3D).
    blending : str
        ``"BEZIER"`` or ``"BSPLINE_UNIFORM"``.
    bspline_order : tuple of int or None
        ``BSPLINE_ORDER_I/J(/K)`` for B-spline blending.
    parents, children : tuple of str
    corners : ndarray, shape (n_corners, 2 or 3)
        As written (2D files: the four corners of the lower face, ``x y``).
    control_index : ndarray of int, shape (n_ctrl, 3)
        ``i j k`` of each control point row.
    control_points : ndarray, shape (n_ctrl, 3)
    surface_tags : tuple of str, length n_surf
    surface_ids : ndarray of int64, shape (n_surf,)
        0-based mesh node index (SU2's global index).
    surface_params : ndarray, shape (n_surf, 3)
        Parametric coordinates (u, v, w) in [0, 1].
    """

    tag: str
    level: int
    degree: tuple[int, ...]
    blending: str
    bspline_order: tuple[int, ...] | None
    parents: tuple[str, ...]
    children: tuple[str, ...]
    corners: np.ndarray
    control_index: np.ndarray
    control_points: np.ndarray
    surface_tags: tuple[str, ...]
    surface_ids: np.ndarray
    surface_params: np.ndarray

    @property
    def orders(self) -> tuple[int, int, int]:
        """Control points per direction (in 2D the third direction has 2, at z = -0.5 and 0.5)."""
        d = list(self.degree) + [1] * (3 - len(self.degree))
        return (d[0] + 1, d[1] + 1, d[2] + 1)

    def net(self) -> np.ndarray:
        """The control points as an (n0, n1, n2, 3) array."""
        n = self.orders
        net = np.full((*n, 3), np.nan)
        idx = self.control_index
        if (idx < 0).any() or (idx >= np.array(n)).any():
            raise ValueError(f"control point index outside the box's {n[0]} x {n[1]} x {n[2]} points")
        net[idx[:, 0], idx[:, 1], idx[:, 2]] = self.control_points
        if np.isnan(net).any():
            raise ValueError(f"the box lists {len(idx)} control points, it needs {n[0] * n[1] * n[2]}")
        return net

    def axis_degrees(self) -> tuple[int, int, int]:
        """Polynomial degree of the blending per direction."""
        n = self.orders
        if self.blending == "BSPLINE_UNIFORM":
            order = list(self.bspline_order or (2, 2, 2)) + [2] * 3
            return tuple(min(int(order[a]) - 1, n[a] - 1) for a in range(3))
        return (n[0] - 1, n[1] - 1, n[2] - 1)


@dataclass(frozen=True)
class Su2FfdSection:
    """The whole FFD section: ``FFD_NLEVEL`` and its boxes. ``legacy``: written without FFD_BLENDING."""

    nlevel: int
    boxes: tuple[Su2FfdBox, ...]
    legacy: bool = False


# ----------------------------------------------------------------------------------------------
# reading and writing the text


def find_section(tail: bytes) -> int | None:
    """Offset in ``tail`` of the line ``FFD_NBOX=`` (the start of the FFD section), or None."""
    m = re.search(rb"(?m)^[ \t]*FFD_NBOX[ \t]*=", tail)
    return None if m is None else m.start()


class _SectionReader:
    """The lines of an FFD section read in order: ``KEY= value`` lines, counts, rows of numbers, and the
    error naming the file and the line."""

    def __init__(self, text: str, path, first_line: int):
        self.lines, self.pos, self.path, self.first_line = text.splitlines(), 0, path, first_line

    def fail(self, msg, k=None):
        line = self.first_line + (self.pos if k is None else k)
        raise InputError(f"SU2 FFD section: {msg}", path=self.path, line=line,
                         hint="ffd must update or drop this section; fix it or remove the FFD_ lines")

    def key_line(self, expect=None, optional=False):
        lines = self.lines
        while self.pos < len(lines) and not lines[self.pos].strip():
            self.pos += 1
        if self.pos >= len(lines):
            if optional:
                return None, None
            self.fail(f"the file ends where {expect or 'a KEY= line'} was expected")
        m = _KEY.match(lines[self.pos])
        if m is None:
            if optional:
                return None, None
            self.fail(f"expected {expect or 'a KEY= line'}, got {lines[self.pos][:40]!r}")
        key, value = m.group(1), m.group(2)
        if expect is not None and key != expect:
            if optional:
                return None, None
            self.fail(f"expected {expect}=, got {key}=")
        self.pos += 1
        return key, value

    def integer(self, value, what):
        try:
            return int(value.split()[0])
        except (ValueError, IndexError):
            self.fail(f"{what}: expected a whole number, got {value[:40]!r}", self.pos - 1)

    def count(self, key):
        """The whole number of the ``key=`` line that comes next."""
        return self.integer(self.key_line(key)[1], key)

    def rows(self, n, what):
        out = self.lines[self.pos:self.pos + n]
        if len(out) < n:
            self.fail(f"{what}: {n} rows announced, the file ends after {len(out)}")
        self.pos += n
        return out

    def numbers(self, key, ncols):
        """The rows announced by the ``key=`` line that comes next, as an (n, ncols) array."""
        n = self.count(key)
        start = self.pos
        block = self.rows(n, key)
        try:
            arr = np.array([r.split()[:ncols] for r in block], dtype=np.float64)
        except ValueError:
            self.fail(f"{key}: expected {ncols} numbers per row", start)
        if arr.shape != (len(block), ncols):
            self.fail(f"{key}: expected {ncols} numbers per row", start)
        return arr


def parse_section(text: str, ndim: int, *, path=None, first_line: int = 1) -> Su2FfdSection:
    """Parse an FFD section (from its ``FFD_NBOX=`` line to the end of the file).

    Raises :class:`InputError` naming the file and line when the section is not in SU2's form.
    """
    r = _SectionReader(text, path, first_line)
    nbox = r.count("FFD_NBOX")
    nlevel = r.count("FFD_NLEVEL")
    boxes = [_read_box(r, ndim) for _ in range(nbox)]
    return Su2FfdSection(nlevel=nlevel, boxes=tuple(b for b, _ in boxes), legacy=any(old for _, old in boxes))


def _read_box(r: _SectionReader, ndim: int) -> tuple[Su2FfdBox, bool]:
    """One box of the section, and whether it is in the pre-4.3 form (no ``FFD_BLENDING``)."""
    _, tag = r.key_line("FFD_TAG")
    level = r.count("FFD_LEVEL")
    degree = tuple(r.count(f"FFD_DEGREE_{axis}") for axis in "IJK"[:ndim])
    k, v = r.key_line("FFD_BLENDING", optional=True)
    blending, order = "BEZIER", None
    if k is not None:
        blending = v.split()[0].upper() if v.split() else ""
        if blending not in ("BEZIER", "BSPLINE_UNIFORM"):
            r.fail(f"FFD_BLENDING must be BEZIER or BSPLINE_UNIFORM, got {v!r}", r.pos - 1)
        if blending == "BSPLINE_UNIFORM":
            order = tuple(r.count(f"BSPLINE_ORDER_{axis}") for axis in "IJK"[:ndim])
    parents = tuple(x.strip() for x in r.rows(r.count("FFD_PARENTS"), "FFD_PARENTS"))
    children = tuple(x.strip() for x in r.rows(r.count("FFD_CHILDREN"), "FFD_CHILDREN"))
    corners = r.numbers("FFD_CORNER_POINTS", ndim)
    cp = r.numbers("FFD_CONTROL_POINTS", 6)
    n = r.count("FFD_SURFACE_POINTS")
    start = r.pos
    parts = [x.split() for x in r.rows(n, "FFD_SURFACE_POINTS")]
    if any(len(p) < 5 for p in parts):
        r.fail("FFD_SURFACE_POINTS: expected 'MARKER point u v w' per row", start)
    try:
        ids = np.array([p[1] for p in parts], dtype=np.int64)
        params = np.array([p[2:5] for p in parts], dtype=np.float64).reshape(-1, 3)
    except ValueError:
        r.fail("FFD_SURFACE_POINTS: expected 'MARKER point u v w' per row", start)
    box = Su2FfdBox(tag=tag.strip(), level=level, degree=degree, blending=blending, bspline_order=order,
                    parents=parents, children=children, corners=corners,
                    control_index=cp[:, :3].astype(np.int64), control_points=cp[:, 3:6],
                    surface_tags=tuple(p[0] for p in parts), surface_ids=ids, surface_params=params)
    return box, k is None


def format_section(section: Su2FfdSection, ndim: int) -> str:
    """The text of an FFD section as SU2 8 writes it (LF line endings, tab separated)."""
    out = [f"FFD_NBOX= {len(section.boxes)}", f"FFD_NLEVEL= {section.nlevel}"]
    for b in section.boxes:
        out += [f"FFD_TAG= {b.tag}", f"FFD_LEVEL= {b.level}"]
        out += [f"FFD_DEGREE_{a}= {d}" for a, d in zip("IJK", b.degree, strict=False)]
        out.append(f"FFD_BLENDING= {b.blending}")
        if b.blending == "BSPLINE_UNIFORM":
            out += [f"BSPLINE_ORDER_{a}= {k}" for a, k in zip("IJK", b.bspline_order or (), strict=False)]
        out.append(f"FFD_PARENTS= {len(b.parents)}")
        out += list(b.parents)
        out.append(f"FFD_CHILDREN= {len(b.children)}")
        out += list(b.children)
        out.append(f"FFD_CORNER_POINTS= {len(b.corners)}")
        out += ["\t".join(f"{x:.15g}" for x in row) for row in b.corners]
        out.append(f"FFD_CONTROL_POINTS= {len(b.control_points)}")
        out += [f"{i}\t{j}\t{k}\t{x:.15g}\t{y:.15g}\t{z:.15g}"
                for (i, j, k), (x, y, z) in zip(b.control_index.tolist(), b.control_points.tolist(),
                                                strict=True)]
        out.append(f"FFD_SURFACE_POINTS= {len(b.surface_ids)}")
        out += [f"{t}\t{p}\t{u:.15e}\t{v:.15e}\t{w:.15e}"
                for t, p, (u, v, w) in zip(b.surface_tags, b.surface_ids.tolist(), b.surface_params.tolist(),
                                           strict=True)]
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------------------------
# the box as a map from parameters to points


def _axis_basis(n: int, p: int, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dense basis values and first derivatives, each (N, n), of a clamped uniform spline of degree p."""
    knots = clamped_knots(n, p)
    first, ders = basis_derivs(knots, p, np.clip(t, 0.0, 1.0), 1)
    rows = np.arange(len(t))[:, None]
    cols = first[:, None] + np.arange(p + 1)[None, :]
    B = np.zeros((len(t), n))
    dB = np.zeros((len(t), n))
    B[rows, cols] = ders[0]
    dB[rows, cols] = ders[1]
    return B, dB


def evaluate(box: Su2FfdBox, params: np.ndarray, *, jacobian: bool = False):
    """Points (N, 3) of the box at parameters (N, 3) in [0, 1]; with ``jacobian``, also dX/du (N, 3, 3)."""
    net = box.net()
    n, p = box.orders, box.axis_degrees()
    params = np.asarray(params, dtype=np.float64).reshape(-1, 3)
    X = np.empty((len(params), 3))
    J = np.empty((len(params), 3, 3)) if jacobian else None
    for a in range(0, len(params), CHUNK):
        t = params[a:a + CHUNK]
        (B0, D0), (B1, D1), (B2, D2) = (_axis_basis(n[k], p[k], t[:, k]) for k in range(3))
        X[a:a + CHUNK] = np.einsum("ni,nj,nk,ijkd->nd", B0, B1, B2, net, optimize=True)
        if jacobian:
            J[a:a + CHUNK, :, 0] = np.einsum("ni,nj,nk,ijkd->nd", D0, B1, B2, net, optimize=True)
            J[a:a + CHUNK, :, 1] = np.einsum("ni,nj,nk,ijkd->nd", B0, D1, B2, net, optimize=True)
            J[a:a + CHUNK, :, 2] = np.einsum("ni,nj,nk,ijkd->nd", B0, B1, D2, net, optimize=True)
    return (X, J) if jacobian else X


def invert(box: Su2FfdBox, points: np.ndarray, start: np.ndarray, *, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Parameters (N, 3) of ``points`` (N, 3) in the box, by damped Newton from ``start`` (N, 3).

    Vectorised over the points; parameters are kept in a slightly enlarged cube so that a point just
    outside the box converges to a parameter just outside [0, 1] (which tells it is outside). Returns
    the parameters and the residual |X(u) - x| (N,).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    u = np.clip(np.asarray(start, dtype=np.float64).reshape(-1, 3), 0.0, 1.0).copy()
    active = np.ones(len(pts), dtype=bool)
    res = np.full(len(pts), np.inf)
    for _ in range(NEWTON_ITERATIONS):
        idx = np.flatnonzero(active)
        if not len(idx):
            break
        X, J = evaluate(box, u[idx], jacobian=True)
        r = pts[idx] - X
        res[idx] = np.linalg.norm(r, axis=1)
        # In 2D boxes the third direction is linear in z (J[:, 2, 2] > 0), so J is never singular there.
        try:
            step = np.linalg.solve(J, r[..., None])[..., 0]
        except np.linalg.LinAlgError:
            step = np.linalg.lstsq(J.reshape(-1, 3), r.reshape(-1), rcond=None)[0].reshape(-1, 3)
        step = np.clip(step, -0.25, 0.25)
        u[idx] = np.clip(u[idx] + step, -0.05, 1.05)
        done = (np.abs(step).max(axis=1) < 1e-15) | (res[idx] <= 1e-4 * tol)
        active[idx[done]] = False
    # Extrapolated parameters (outside [0, 1]) are evaluated on the clipped cube: a point outside keeps
    # a residual that says so.
    X = evaluate(box, np.clip(u, 0.0, 1.0))
    res = np.linalg.norm(pts - X, axis=1)
    return u, res


def refresh(section: Su2FfdSection, points: np.ndarray, *, tol: float = SU2_FFD_TOL
            ) -> tuple[Su2FfdSection, dict]:
    """The section with every box's ``FFD_SURFACE_POINTS`` recomputed for the mesh nodes ``points`` (N, 3).

    The control points and everything else stay as they are. A listed node that no longer lies in its
    box (parameters outside [-tol, 1 + tol], or a residual above :data:`RESIDUAL_TOL` x the box's
    diagonal) is dropped from the list. Returns the new section and a report ``{"boxes": [{"tag", "points", "outside",
    "residual"}], "outside": total}``.
    """
    points = np.asarray(points, dtype=np.float64)
    boxes, report = [], []
    for box in section.boxes:
        ids = box.surface_ids
        if len(ids) and (ids.min() < 0 or ids.max() >= len(points)):
            raise InputError(f"SU2 FFD box {box.tag}: surface point ids outside the mesh's "
                             f"0..{len(points) - 1}")
        size = diagonal(box.control_points)
        u, res = invert(box, points[ids], box.surface_params, tol=RESIDUAL_TOL * size)
        inside = np.all(u >= -tol, axis=1) & np.all(u <= 1.0 + tol, axis=1) & (res <= RESIDUAL_TOL * size)
        u = np.clip(u, tol, 1.0 - tol)
        keep = np.flatnonzero(inside)
        boxes.append(replace(box, surface_tags=tuple(box.surface_tags[i] for i in keep),
                             surface_ids=ids[keep], surface_params=u[keep]))
        report.append({"tag": box.tag, "points": int(len(keep)), "outside": int(len(ids) - len(keep)),
                       "residual": float(res[keep].max(initial=0.0))})
    return (Su2FfdSection(nlevel=section.nlevel, boxes=tuple(boxes), legacy=False),
            {"boxes": report, "outside": int(sum(r["outside"] for r in report)),
             "legacy": bool(section.legacy)})


def describe(report: dict) -> str:
    """One line for a run's summary: what was done to the mesh's SU2 FFD section."""
    if "dropped" in report:
        return report["dropped"]
    boxes = ", ".join(f"{b['tag']} {b['points']} points" + (f" ({b['outside']} now outside, left out)"
                                                           if b["outside"] else "")
                      for b in report["boxes"])
    old = "; rewritten in SU2 8's form (FFD_BLENDING added)" if report.get("legacy") else ""
    return f"FFD_SURFACE_POINTS recomputed for the deformed surface: {boxes}{old}"
