"""Wing surfaces and small hexahedral wing volumes in plain NumPy (fixtures; no gmsh).

Used as exact geometry oracles in the tests and the benchmarks: every function here is a closed-form
or vectorised construction whose leading edge, trailing edge, chord, twist, sweep and dihedral are
known exactly. The pieces live in their own modules and are re-exported here, so that
``from ffdcli.testing.wings import Planform, naca4, surface_mesh`` keeps working:

- :mod:`ffdcli.testing.naca` NACA 4-digit sections (Selig order);
- :mod:`ffdcli.testing.planform` :class:`Planform` (sweep, dihedral, taper, twist, kink; any axes);
- :mod:`ffdcli.testing.ogrid` 2D O-grids of quads around an airfoil;
- :mod:`ffdcli.testing.cells` signed cell sizes (the test of inversion);
- this module: wing surfaces (:func:`wing_surface`, :func:`surface_mesh`) and a structured
  hexahedral wing (:func:`extruded_wing_mesh`, an O-grid extruded along the span).

The tetrahedral (and prism-layer) volume meshes made with gmsh are :mod:`ffdcli.testing.gmsh_wings`.
"""

from __future__ import annotations

import numpy as np

from ffdcli.mesh import CellBlock, Mesh
from ffdcli.testing.cells import hex_volumes, quad_areas, tet_volumes
from ffdcli.testing.naca import (
    NACA4_CLOSED_TE_A4,
    NACA4_COEFFS,
    Naca4,
    naca4,
    naca4_camber,
    naca4_points,
    naca4_surfaces,
    naca4_symmetric_area,
    naca4_thickness,
    parse_naca4,
    polygon_area,
)
from ffdcli.testing.ogrid import airfoil_ogrid, airfoil_ogrid_mesh
from ffdcli.testing.planform import Planform, crm_planform, rect_wing_planform

__all__ = [
    "NACA4_CLOSED_TE_A4", "NACA4_COEFFS", "Naca4", "Planform", "airfoil_ogrid", "airfoil_ogrid_mesh",
    "crm_planform", "extruded_wing_mesh", "hex_volumes", "leading_edge_ids", "naca4", "naca4_camber",
    "naca4_points", "naca4_surfaces", "naca4_symmetric_area", "naca4_thickness", "parse_naca4",
    "polygon_area", "quad_areas", "rect_wing_planform", "surface_mesh", "tet_volumes",
    "trailing_edge_ids", "wing_surface",
]

# ----------------------------------------------------------------------------------------------
# Wing surface mesh
# ----------------------------------------------------------------------------------------------


def _cap_faces(ring: np.ndarray, n_chord: int, blunt: bool) -> tuple[np.ndarray, np.ndarray]:
    """Quads and triangles closing one section, oriented counter-clockwise in the local (c, t)
    plane (normal +s). ``ring`` holds the section's point ids in loop order: ring[0] is the upper
    trailing-edge point, ring[n_chord - 1] the leading edge, then the lower side."""
    le = n_chord - 1
    i = np.arange(n_chord)
    upper = ring[le - i]                  # upper side from the leading edge (i = 0) aft
    lower = ring[(le + i) % len(ring)]    # lower side from the leading edge aft; wraps to ring[0]
    # strip between lower[i], lower[i+1], upper[i+1], upper[i]: counter-clockwise
    last = n_chord - 1 if blunt else n_chord - 2          # sharp TE: the last strip is a triangle
    k = np.arange(1, last)
    quads = np.stack([lower[k], lower[k + 1], upper[k + 1], upper[k]], axis=1)
    tris = [np.array([[lower[0], lower[1], upper[1]]])]   # at the leading edge upper[0] == lower[0]
    if not blunt:
        tris.append(np.array([[lower[last], lower[last + 1], upper[last]]]))  # TE: shared last point
    return quads, np.concatenate(tris)


def _surface_faces(planform: Planform, n_chord: int, n_span: int, tip: str, root: str, eta):
    """Points and (kind, faces) lists of marker ``wing`` and (if closed) ``root``; see wing_surface."""
    for name, val in (("tip", tip), ("root", root)):
        if val not in ("closed", "open"):
            raise ValueError(f"{name} must be 'closed' or 'open', got {val!r}")
    if n_chord < 3:
        raise ValueError("n_chord must be at least 3")
    eta = planform.stations(n_span) if eta is None else np.asarray(eta, dtype=np.float64)
    if eta.ndim != 1 or len(eta) < 2 or np.any(np.diff(eta) <= 0):
        raise ValueError("eta must be an increasing 1D array of at least 2 stations")
    coords = planform.airfoil_coords(eta, 2 * n_chord - 1)
    blunt = not planform.closed_te
    if not blunt:
        coords = coords[:, :-1]          # the lower trailing-edge point repeats the upper one
    n_loop = coords.shape[1]
    pts = planform.section_points(eta, coords).reshape(-1, 3)

    ids = np.arange(len(eta) * n_loop).reshape(len(eta), n_loop)
    a = ids[:-1]
    b = np.roll(ids[:-1], -1, axis=1)    # next point around the loop (wraps over the TE)
    quads = np.stack([a, b, np.roll(ids[1:], -1, axis=1), ids[1:]], axis=-1).reshape(-1, 4)
    wing_q, wing_t = [quads], []
    root_q = root_t = None
    if tip == "closed":
        q, t = _cap_faces(ids[-1], n_chord, blunt)
        wing_q.append(q)
        wing_t.append(t)
    if root == "closed":
        q, t = _cap_faces(ids[0], n_chord, blunt)
        root_q, root_t = q[:, ::-1], t[:, ::-1]      # the root cap faces -s
    flip = planform.handedness < 0

    def faces(arrays, width):
        data = np.concatenate(arrays) if arrays else np.zeros((0, width), dtype=np.int64)
        data = data.astype(np.int64)
        return np.ascontiguousarray(data[:, ::-1]) if flip else data

    out = {"wing": (faces(wing_q, 4), faces(wing_t, 3))}
    if root_q is not None:
        out["root"] = (faces([root_q], 4), faces([root_t], 3))
    return pts, out


def wing_surface(planform: Planform, n_chord: int = 41, n_span: int = 21, *, tip: str = "closed",
                 root: str = "open", eta: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Surface of a wing as quads: the sections joined station to station, flat end caps.

    Parameters
    ----------
    planform
        The wing (:class:`Planform`).
    n_chord
        Points per side from the leading edge to the trailing edge, both included (the section
        has ``2 * n_chord - 2`` distinct points when the trailing edge is sharp, ``2 * n_chord - 1``
        when it is blunt: the blunt base is then one face wide).
    n_span, eta
        Spanwise stations: ``planform.stations(n_span)`` unless ``eta`` (increasing, from 0 to 1)
        is given. Station 0 lies exactly in the root plane and the last in the tip plane.
    tip, root
        ``"closed"`` adds a flat cap of the tip (respectively root) section, ``"open"`` leaves it
        open. The default (tip closed, root open) is the wing of a half-wing CFD mesh, open at the
        symmetry plane; both closed, the surface is watertight.

    Returns
    -------
    points : (N, 3) float64
        Station by station, each section in Selig order without a repeated sharp trailing edge;
        point ``j * n_loop + n_chord - 1`` is the leading edge of station ``j`` (see
        :func:`leading_edge_ids`, :func:`trailing_edge_ids`).
    quads : (F, 4) int64
        Faces with their normal out of the wing (for any axes and span sign), side faces first
        (``(n_span - 1) * n_loop``, station by station), then the tip cap, then the root cap. The
        cap faces at the leading edge (and at a sharp trailing edge) are triangles, stored as
        *collapsed quads* whose last two nodes are equal; the diagonal cross product
        ``(p2 - p0) x (p3 - p1)`` is twice the area vector of every face, collapsed or not.
        :func:`surface_mesh` gives the same surface as a :class:`~ffdcli.mesh.Mesh` with separate
        quad and triangle blocks.
    """
    pts, markers = _surface_faces(planform, n_chord, n_span, tip, root, eta)
    quads = []
    for name in ("wing", "root"):
        if name in markers:
            q, t = markers[name]
            quads += [q, np.concatenate([t, t[:, 2:]], axis=1)]
    return pts, np.concatenate(quads)


def surface_mesh(planform: Planform, n_chord: int = 41, n_span: int = 21, *, tip: str = "closed",
                 root: str = "open", eta: np.ndarray | None = None) -> Mesh:
    """The surface of :func:`wing_surface` as a surface-only :class:`~ffdcli.mesh.Mesh`.

    ``dim=3`` (the dimension of the space the surface lives in), no interior cells, marker ``wing``
    (side faces and tip cap) as a ``quad`` and a ``triangle`` block, and, with ``root="closed"``, a
    separate marker ``root`` (so that ``wing`` stays the wing as a half-wing CFD mesh has it).
    Same points and face orientation as :func:`wing_surface`.
    """
    pts, markers = _surface_faces(planform, n_chord, n_span, tip, root, eta)
    return Mesh(points=pts, dim=3, cells=[],
                markers={name: [CellBlock("quad", q), CellBlock("triangle", t)]
                         for name, (q, t) in markers.items()})


def leading_edge_ids(n_chord: int, n_stations: int, closed_te: bool = True) -> np.ndarray:
    """Point ids of the leading-edge points of each station in a :func:`wing_surface` mesh."""
    n_loop = 2 * n_chord - 2 if closed_te else 2 * n_chord - 1
    return np.arange(n_stations) * n_loop + n_chord - 1


def trailing_edge_ids(n_chord: int, n_stations: int, closed_te: bool = True) -> np.ndarray:
    """Point ids of the (upper) trailing-edge point of each station in a :func:`wing_surface` mesh."""
    n_loop = 2 * n_chord - 2 if closed_te else 2 * n_chord - 1
    return np.arange(n_stations) * n_loop


# ----------------------------------------------------------------------------------------------
# Structured hexahedral wing mesh (an O-grid extruded along the span)
# ----------------------------------------------------------------------------------------------


def extruded_wing_mesh(planform: Planform | None = None, n_around: int = 49, n_radial: int = 13,
                       n_span: int = 7, farfield_radius: float = 5.0, first_cell: float = 5e-3,
                       **ogrid_kw) -> Mesh:
    """A small structured hexahedral volume mesh of a wing, made without gmsh.

    The O-grid of :func:`airfoil_ogrid` (unit chord, around the planform's root NACA section) is
    placed at each spanwise station exactly as a wing section: scaled by the local chord, twisted,
    swept and raised by :meth:`Planform.local_points`; the stations are joined by hexahedra. The
    wing therefore spans the whole domain, from the root plane (span 0, marker ``symmetry``) to the
    tip plane (span ``semi_span``, marker ``side``), where it meets the outer boundary. With a
    ``tip_airfoil`` the grids of the root and tip sections are blended linearly in ``eta``.

    Parameters
    ----------
    planform
        Default :func:`rect_wing_planform` (NACA 0012, chord 1 along x, thickness y, span z 0..3).
    n_around, n_radial, farfield_radius, first_cell, ogrid_kw
        Passed to :func:`airfoil_ogrid` (``closed_te`` comes from the planform).
    n_span
        Stations from root to tip (``planform.stations``; the kink, if any, is one of them).

    Returns
    -------
    Mesh
        ``dim=3``, one ``hexahedron`` block (VTK order, positive volume), markers ``wing``,
        ``farfield``, ``symmetry``, ``side`` (``quad`` blocks, normals out of the fluid). Point
        ``j * n_plane + p`` is point ``p`` of the O-grid at station ``j``. The defaults give 4 368
        points and 3 456 cells. Raises ValueError if a cell is inverted (e.g. strong twist between
        few stations).
    """
    pf = rect_wing_planform() if planform is None else planform
    xy, quads, airfoil, farfield = airfoil_ogrid(pf.root_airfoil, n_around, n_radial, farfield_radius,
                                                 first_cell, closed_te=pf.closed_te, **ogrid_kw)
    eta = pf.stations(n_span)
    if pf.tip_airfoil is not None and pf.tip_airfoil != pf.root_airfoil:
        xy_tip = airfoil_ogrid(pf.tip_airfoil, n_around, n_radial, farfield_radius, first_cell,
                               closed_te=pf.closed_te, **ogrid_kw)[0]
        grids = (1.0 - eta[:, None, None]) * xy + eta[:, None, None] * xy_tip
    else:
        grids = np.broadcast_to(xy, (len(eta), *xy.shape))
    n_plane = len(xy)
    pts = pf.section_points(eta, grids).reshape(-1, 3)

    lower = quads[None, :, :] + n_plane * np.arange(len(eta) - 1)[:, None, None]   # (n_span-1, F, 4)
    hexes = np.concatenate([lower, lower + n_plane], axis=-1).reshape(-1, 8)
    if pf.handedness < 0:                        # local (c, t, s) -> mesh is mirrored
        hexes = hexes[:, [0, 3, 2, 1, 4, 7, 6, 5]]
    vol = hex_volumes(pts, hexes)
    if vol.min() <= 0:
        raise ValueError(f"{int(np.sum(vol <= 0))} hexahedra are inverted; use more stations or a "
                         "finer O-grid")

    def side_faces(lines):
        a = lines[None, :, :] + n_plane * np.arange(len(eta) - 1)[:, None, None]
        return np.concatenate([a, a[..., ::-1] + n_plane], axis=-1).reshape(-1, 4)

    faces = {"wing": (side_faces(airfoil), np.arange(len(eta) - 1)[:, None] * len(quads)
                      + np.arange(len(airfoil))[None, :]),
             "farfield": (side_faces(farfield), np.arange(len(eta) - 1)[:, None] * len(quads)
                          + (len(quads) - len(farfield)) + np.arange(len(farfield))[None, :]),
             "symmetry": (quads, np.arange(len(quads))),
             "side": (quads + n_plane * (len(eta) - 1), (len(eta) - 2) * len(quads) + np.arange(len(quads)))}
    markers = {}
    for name, (f, cell) in faces.items():
        markers[name] = [CellBlock("quad", _orient_out(pts, f, hexes[np.ravel(cell)]))]
    return Mesh(points=pts, dim=3, cells=[CellBlock("hexahedron", hexes)], markers=markers)


def _orient_out(points: np.ndarray, faces: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Quads ``faces`` reordered where needed so that their normal points away from the centroid of
    their cell (``cells[f]``), i.e. out of the fluid."""
    p = points[faces]
    normal = np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])
    out = np.einsum("ij,ij->i", normal, p.mean(axis=1) - points[cells].mean(axis=1)) > 0
    return np.where(out[:, None], faces, faces[:, ::-1])
