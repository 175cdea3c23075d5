"""The hybrid mesh family of ADODG Case 3: a structured, anisotropic wing surface, prism layers, tetrahedra.

Why: on the isotropic tetrahedra of :mod:`benchmarks.adodg.case3_meshes` the leading-edge radius
(1.1019 t^2 = 0.0159 chord for the NACA 0012) spans about one edge, the stagnation pressure is not
reached and the zero-lift drag is negative and larger than the induced drag the case is about
(docs/adodg-case3.md). Resolving the leading edge with isotropic cells everywhere is unaffordable
here; this family puts the small cells only where they are needed, chordwise:

- **Wing surface** (NumPy, exact NACA 0012 with the sharp-trailing-edge polynomial): the same chordwise
  stations on the upper and lower sides, spaced by arc length from ``ds_le`` at the leading edge
  (about a tenth of the leading-edge radius) and ``ds_te`` at the trailing edge, growing by at most
  ``growth`` from one edge to the next up to ``ds_max``; spanwise stations from ``dy_max`` at the root
  to ``dy_tip`` at the tip. Each quadrilateral is split into two triangles. The rounded tip cap (the
  tip section's upper half revolved by 180 degrees about the chord line, outboard: points
  ``(x, 3 + y_t(x) sin(phi), y_t(x) cos(phi))``) is the same chordwise stations times ``n_phi``
  divisions in phi, its quadrilaterals at the leading- and trailing-edge poles reduced to triangles.
- **Prism layers** (NumPy): ``layers`` wedges per wall triangle, 0.4 chord thick in all
  (:data:`LAYERS_HEIGHT`), built from one grid in the section plane (:func:`section_grid`): layer k
  lies on the section's offset curve at distance ``h_k = first * (1 + g + ... + g^(k-1))`` (the
  boundary of the section grown by a disc of radius h_k: normal offsets of the sides and an arc about
  the sharp trailing edge); its stations are the wall stations' normal offsets, moved along the curve
  near the edges only (:func:`top_fractions`: round the leading edge spread to half the top layer's
  height, the arc over the trailing edge shared among its neighbours), by a weight growing linearly
  with h_k. The grid is mapped onto the wing as the wall is (the upper and lower sides at each
  spanwise station; the cap by the same revolution about the chord line), so the layers follow the
  cap exactly and stay in the symmetry plane at the root; the leading- and trailing-edge stations
  stay on the chord line, the cap's poles. Not a boundary layer (the flow is inviscid): the layers
  carry the wall's chordwise clustering into the field, so the flow round the leading edge (whose
  pressures the drag is a small difference of) is on cells ``ds_le`` chordwise there, growing with
  the distance, instead of on tetrahedra. The section is convex, so the layers cannot fold.
- **Tetrahedra** (gmsh, one thread): the top of the prism layers is handed to gmsh as a discrete
  surface (its nodes are kept), closed by the symmetry plane (y = 0, with the layers' section as a
  hole) and the far-field box; gmsh fills the box with tetrahedra whose size grows from the top
  layer's height (``h_near``) by 0.25 per chord of distance to ``h_far``.

Markers ``wing`` (triangles), ``symmetry`` (triangles and the layers' quadrilaterals), ``farfield``;
cells tetra and wedge in VTK order with positive volume; boundary faces oriented out of the fluid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq
from scipy.spatial import cKDTree

from ffdcli.mesh import CellBlock, Mesh
from ffdcli.quality.metrics import cell_quality
from ffdcli.testing.cells import tet_volumes
from ffdcli.testing.gmsh_wings import orient_out_of_fluid
from ffdcli.testing.naca import naca4_thickness

#: Chord, semispan (the ADODG Case 3 wing) and the section.
CHORD, SEMISPAN, SECTION = 1.0, 3.0, "0012"
#: The NACA 4-digit leading-edge radius, 1.1019 t^2 (chords).
LE_RADIUS = 1.1019 * 0.12 ** 2


@dataclass(frozen=True)
class HybridLevel:
    """Sizes of one level of the hybrid family, in chords (module docstring): wall spacings along the
    chord (``ds_le``, ``ds_te``, ``ds_max``, growing by ``growth``) and the span (``dy_max`` at the
    root, ``dy_tip`` at the tip and round the cap); ``layers`` prism layers from ``first`` growing by
    ``layer_growth``, their stations moved toward the top's target by ``relax (h / h_top)^relax_power``;
    tetrahedra from ``h_near`` at the layers' top to ``h_far``."""

    name: str
    ds_le: float
    ds_te: float
    ds_max: float
    dy_max: float
    dy_tip: float
    growth: float
    first: float
    layers: int
    layer_growth: float
    h_near: float
    h_far: float
    relax: float = 1.0
    relax_power: float = 1.0


def graded(length: float, d0: float, d1: float, dmax: float, growth: float) -> np.ndarray:
    """Stations (n + 1,) from 0 to ``length``: spacing ``d0`` at 0 and ``d1`` at ``length``, growing
    geometrically by ``growth`` per interval from each end, at most ``dmax``. The station density is
    that of the geometric series (the k-th station of ``d0 g^k`` at ``s = d0 (g^k - 1) / (g - 1)``: a
    density ``ln g / (g - 1) / (d0 + (g - 1) s)``), capped by ``1 / dmax``; the interval count is
    rounded and the stations stretched to fit."""
    s = np.linspace(0.0, length, 200_001)
    c = np.log(growth) / (growth - 1.0)
    delta = np.minimum(dmax, c * np.minimum(d0 + (growth - 1.0) * s, d1 + (growth - 1.0) * (length - s)))
    inv = 1.0 / delta
    n = np.concatenate([[0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(s))])
    count = max(2, int(round(n[-1])))
    out = np.interp(np.linspace(0.0, n[-1], count + 1), n, s)
    out[0], out[-1] = 0.0, length
    return out


def chord_stations(level: HybridLevel) -> tuple[np.ndarray, np.ndarray]:
    """Chordwise stations x (n + 1,) from the leading edge (0) to the trailing edge (1), spaced by arc
    length along the section's upper side, and the half-thickness y_t there."""
    theta = np.linspace(0.0, np.pi, 400_001)
    x = 0.5 * (1.0 - np.cos(theta))
    z = naca4_thickness(SECTION, x)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(z)))])
    s = graded(float(arc[-1]), level.ds_le, level.ds_te, level.ds_max, level.growth)
    xs = np.interp(s, arc, x)
    xs[0], xs[-1] = 0.0, 1.0
    return xs * CHORD, naca4_thickness(SECTION, xs) * CHORD


def wing_surface(level: HybridLevel) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """The wall: points (W, 3), triangles (F, 3) with their normals out of the wing (into the fluid),
    and per-node arrays: ``station`` (W,) the chordwise station, ``y0`` (W,) and ``sc`` (W, 2) that
    place a section point (X, Z) of that station as ``(X, y0 + Z s, Z c)`` (upper side s, c = 0, 1;
    lower side 0, -1; tip cap sin(phi), cos(phi), y0 = semispan), ``root`` (the root section's nodes
    in loop order: upper side leading edge -> trailing edge, then the lower side back)."""
    xs, yt = chord_stations(level)
    n = len(xs) - 1
    ys = graded(SEMISPAN, level.dy_max, level.dy_tip, level.dy_max, level.growth)
    ns = len(ys) - 1
    n_phi = max(4, int(np.ceil(np.pi * yt.max() / level.dy_tip)))
    up = np.arange((n + 1) * (ns + 1)).reshape(n + 1, ns + 1)
    count = up.size
    lo = up.copy()
    lo[1:n] = count + np.arange((n - 1) * (ns + 1)).reshape(n - 1, ns + 1)
    count += (n - 1) * (ns + 1)
    cap = np.empty((n + 1, n_phi + 1), dtype=np.int64)
    cap[:, 0], cap[:, n_phi] = up[:, ns], lo[:, ns]
    cap[0, :], cap[n, :] = up[0, ns], up[n, ns]
    cap[1:n, 1:n_phi] = count + np.arange((n - 1) * (n_phi - 1)).reshape(n - 1, n_phi - 1)
    count += (n - 1) * (n_phi - 1)
    station = np.empty(count, dtype=np.int64)
    y0 = np.empty(count)
    sc = np.empty((count, 2))
    ii = np.broadcast_to(np.arange(n + 1)[:, None], up.shape)
    station[up], y0[up], sc[up] = ii, np.broadcast_to(ys, up.shape), (0.0, 1.0)
    station[lo[1:n]], y0[lo[1:n]], sc[lo[1:n]] = ii[1:n], np.broadcast_to(ys, up.shape)[1:n], (0.0, -1.0)
    phi = np.linspace(0.0, np.pi, n_phi + 1)[1:n_phi]
    inner = cap[1:n, 1:n_phi]
    station[inner] = np.broadcast_to(np.arange(1, n)[:, None], inner.shape)
    y0[inner] = SEMISPAN
    sc[inner] = np.stack(np.broadcast_arrays(np.sin(phi)[None, :], np.cos(phi)[None, :]), axis=-1)
    pts = place(xs[station], yt[station], y0, sc)
    tris = np.concatenate([_split(up), _split(lo), _split(cap)])
    tris = tris[(tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])]
    # orient out of the wing: the wing is convex, so every face looks away from an inner point
    p = pts[tris]
    nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    mid = np.array([0.5 * CHORD, 0.5 * SEMISPAN, 0.0])
    flip = np.einsum("ij,ij->i", nrm, p.mean(axis=1) - mid) < 0
    tris[flip] = tris[flip][:, [0, 2, 1]]
    root = np.concatenate([up[:, 0], lo[n - 1:0:-1, 0]])
    return pts, tris, {"root": root, "station": station, "y0": y0, "sc": sc}


def place(x: np.ndarray, z: np.ndarray, y0: np.ndarray, sc: np.ndarray) -> np.ndarray:
    """Points (W, 3) ``(x, y0 + z s, z c)`` of section points (x, z) (W,) on their planes (above)."""
    y = y0 + z * sc[:, 0]
    out = np.stack([x, y, z * sc[:, 1]], axis=-1)
    out[sc[:, 0] == 0.0, 1] = y0[sc[:, 0] == 0.0]          # exactly in their planes (the root: y = 0)
    return out


def _split(grid: np.ndarray) -> np.ndarray:
    """The triangles (2 (m-1)(k-1), 3) of a structured (m, k) grid of node ids, each quad split along
    its (i, j)-(i+1, j+1) diagonal; degenerate triangles (a pole) are dropped by the caller."""
    a, b, c, d = grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]
    return np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])


def offset_curve(h: float, dense: int = 40_001) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The upper half of the section's offset at distance ``h`` (the boundary of the section grown by
    a disc of radius h): a dense polyline (M, 2) from (-h, 0) to (1 + h, 0) (the normal offsets of
    the upper side's ``dense`` points of :func:`_dense_section`, then the arc about the sharp trailing
    edge), its arc-length fraction (M,), and the fractions (dense,) of those normal offsets."""
    x, z, nx, nz = _dense_section(dense)
    body = np.stack([x + h * nx, z + h * nz], axis=-1)
    beta = np.linspace(np.arctan2(nz[-1], nx[-1]), 0.0, 200)[1:]
    arc = np.stack([CHORD + h * np.cos(beta), h * np.sin(beta)], axis=-1)
    poly = np.concatenate([body, arc])
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(poly, axis=0), axis=1))])
    frac = length / length[-1]
    return poly, frac, frac[: len(body)]


def _dense_section(dense: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The upper side at ``dense`` cosine-spaced stations: x, z, and the unit outward normal."""
    theta = np.linspace(0.0, np.pi, dense)
    x = 0.5 * (1.0 - np.cos(theta)) * CHORD
    z = naca4_thickness(SECTION, x / CHORD) * CHORD
    tx, tz = np.gradient(x, theta), np.gradient(z, theta)
    ln = np.hypot(tx, tz)
    return x, z, -tz / ln, tx / ln


def section_grid(level: HybridLevel) -> tuple[np.ndarray, np.ndarray]:
    """The layers' points in the section plane, X and Z (layers + 1, n + 1) over the chordwise
    stations. Layer k lies on the offset curve at distance ``h_k``, its stations at the wall
    stations' normal offsets blended by the weight ``relax (h_k / h_top)^relax_power`` toward the
    top's target (:func:`top_fractions`: the normal offsets, spread round the leading edge to half the
    top layer's height, the gap over the trailing edge's arc shared out among its neighbours). The
    leading- and trailing-edge stations stay on the chord line (Z = 0): the tip cap's poles."""
    xs, _ = chord_stations(level)
    g = level.layer_growth
    heights = level.first * np.concatenate([[0.0], np.cumsum(g ** np.arange(level.layers))])
    xd = _dense_section(40_001)[0]
    n = len(xs) - 1
    gx = np.empty((level.layers + 1, n + 1))
    gz = np.empty_like(gx)
    natural = []
    for h in heights:
        poly, frac, body_frac = offset_curve(h)
        wall = np.interp(xs, xd, body_frac)
        wall[-1] = 1.0
        natural.append((poly, frac, wall))
    poly, frac, wall = natural[-1]
    top_h = heights[-1] - heights[-2]
    target = top_fractions(poly, frac, wall, 0.5 * top_h, max(level.ds_max, top_h))
    for k, (h, (poly, frac, wall)) in enumerate(zip(heights, natural, strict=True)):
        w = level.relax * (h / heights[-1]) ** level.relax_power
        a = (1.0 - w) * wall + w * target
        gx[k] = np.interp(a, frac, poly[:, 0])
        gz[k] = np.interp(a, frac, poly[:, 1])
        gz[k, [0, -1]] = 0.0
    gx[0] = xs
    gz[0] = naca4_thickness(SECTION, xs / CHORD) * CHORD
    return gx, gz


def top_fractions(poly: np.ndarray, frac: np.ndarray, wall: np.ndarray, lo: float, hi: float,
                  spread: float = 0.3) -> np.ndarray:
    """Arc fractions (n + 1,) of the top layer's stations: the wall stations' normal offsets
    ``wall`` (n + 1,) on the top's offset curve (``poly``, ``frac`` of :func:`offset_curve`), with the
    intervals within ``spread`` chords of arc from either edge brought into [lo, hi]: round the
    leading edge the offsets of the wall's clustered stations are closer than the layers' top height
    (raised to ``lo``), over the sharp trailing edge one interval spans the arc about it, about 1.4
    times the layers' height (cut to ``hi``). What an interval gains or loses is taken from or given to
    the others of its end, so the stations move only near the edges."""
    length = float(np.sum(np.linalg.norm(np.diff(poly, axis=0), axis=1)))
    pos = wall * length
    d = np.diff(pos)
    mid = 0.5 * (pos[1:] + pos[:-1])
    for region in (mid < spread, mid > length - spread):
        t = np.clip(d, lo, hi)
        change = float(np.sum((t - d)[region]))
        free = region & (d > lo) & (d < hi)
        if change > 0.0:
            give = np.where(free, t - lo, 0.0)
        else:
            give = np.where(free, hi - t, 0.0)
        if give.sum() > abs(change):
            t = t - np.sign(change) * abs(change) * give / give.sum()
            d = np.where(region, t, d)
    return np.concatenate([[0.0], np.cumsum(d)]) / d.sum()


def prism_layers(wall: np.ndarray, tris: np.ndarray, ids: dict[str, np.ndarray], level: HybridLevel
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points of all layers ((layers + 1) W, 3; layer k's node i at k W + i), the wedges
    (layers F, 6) in VTK order, and the symmetry quadrilaterals (layers R, 4) out of the fluid."""
    nw = len(wall)
    gx, gz = section_grid(level)
    st = ids["station"]
    layers = np.stack([place(gx[k, st], gz[k, st], ids["y0"], ids["sc"]) for k in range(level.layers + 1)])
    layers[0] = wall
    base = tris[:, [0, 2, 1]]         # VTK: the base triangle's normal points away from the top one
    wedges = np.concatenate([np.concatenate([base + k * nw, base + (k + 1) * nw], axis=1)
                             for k in range(level.layers)])
    root = ids["root"]
    e0, e1 = root, np.roll(root, -1)
    quads = np.concatenate([np.stack([e0 + k * nw, e1 + k * nw, e1 + (k + 1) * nw, e0 + (k + 1) * nw], -1)
                            for k in range(level.layers)])
    pts = layers.reshape(-1, 3)
    q = pts[quads]
    qn = np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 1])
    quads = np.where((qn[:, 1] < 0)[:, None], quads, quads[:, ::-1])     # out of the fluid: -y
    return pts, wedges, quads


def box(farfield: float) -> tuple[np.ndarray, np.ndarray]:
    """The far-field box corners: ``farfield`` semispans from the wing on every side but the root plane."""
    d = farfield * SEMISPAN
    return np.array([-d, 0.0, -d]), np.array([CHORD + d, SEMISPAN + 0.06 + d, d])


def outer_tets(top: np.ndarray, top_tris: np.ndarray, loop: np.ndarray, lo: np.ndarray, hi: np.ndarray,
               size_near: float, size_growth: float, h_far: float, name: str
               ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """gmsh tetrahedra between the discrete surface (``top`` (K, 3), ``top_tris`` (F, 3) local ids,
    its boundary the closed ``loop`` of local ids in the plane y = 0) and the box ``lo``..``hi``.

    Returns the points (first the K of ``top``, unchanged, then gmsh's new nodes), the tetrahedra
    (positive volume) and the triangles of ``symmetry`` and ``farfield`` (out of the fluid). The size
    grows from ``size_near`` by ``size_growth`` per unit distance from the wing's chord plane to
    ``h_far``.
    """
    import gmsh  # noqa: PLC0415 (the [test] or [samples] extra)

    k_top = len(top)
    te_pos = int(np.argmax(top[loop, 0]))
    gmsh.initialize(["-nt", "1"], readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add(name)
        le_node, te_node = int(loop[0]) + 1, int(loop[te_pos]) + 1     # the loop starts at the leading edge
        # the discrete entities' tags are far above the built-in kernel's own (it numbers from 1)
        pa, pb, ca, cb, sd = 10_001, 10_002, 10_001, 10_002, 10_001
        for tag, node in ((pa, le_node), (pb, te_node)):
            gmsh.model.addDiscreteEntity(0, tag)
            gmsh.model.setCoordinates(tag, *top[node - 1])
        gmsh.model.addDiscreteEntity(1, ca, [pa, pb])
        gmsh.model.addDiscreteEntity(1, cb, [pb, pa])
        gmsh.model.addDiscreteEntity(2, sd, [ca, cb])
        gmsh.model.mesh.addNodes(2, sd, np.arange(1, k_top + 1), top.ravel())
        closed = np.append(loop, loop[0]) + 1
        gmsh.model.mesh.addElementsByType(pa, 15, [], [le_node])
        gmsh.model.mesh.addElementsByType(pb, 15, [], [te_node])
        seg1 = closed[: te_pos + 1]
        seg2 = closed[te_pos:]
        gmsh.model.mesh.addElementsByType(ca, 1, [], np.stack([seg1[:-1], seg1[1:]], -1).ravel())
        gmsh.model.mesh.addElementsByType(cb, 1, [], np.stack([seg2[:-1], seg2[1:]], -1).ravel())
        gmsh.model.mesh.addElementsByType(sd, 2, [], (top_tris + 1).ravel())
        gmsh.model.mesh.reclassifyNodes()
        geo = gmsh.model.geo
        c = [[lo[0], lo[1], lo[2]], [hi[0], lo[1], lo[2]], [hi[0], lo[1], hi[2]], [lo[0], lo[1], hi[2]]]
        p0 = [geo.addPoint(*q) for q in c]
        p1 = [geo.addPoint(q[0], hi[1], q[2]) for q in c]
        b0 = [geo.addLine(p0[i], p0[(i + 1) % 4]) for i in range(4)]
        b1 = [geo.addLine(p1[i], p1[(i + 1) % 4]) for i in range(4)]
        v = [geo.addLine(p0[i], p1[i]) for i in range(4)]
        sym = geo.addPlaneSurface([geo.addCurveLoop(b0), geo.addCurveLoop([ca, cb])])
        far = [geo.addPlaneSurface([geo.addCurveLoop(b1)])]
        for i in range(4):
            far.append(geo.addPlaneSurface([geo.addCurveLoop([b0[i], v[(i + 1) % 4], -b1[i], -v[i]])]))
        vol = geo.addVolume([geo.addSurfaceLoop([sym, *far, sd])])
        geo.synchronize()
        dx = f"((Fabs(x - {0.5 * CHORD}) - {0.5 * CHORD}) + Fabs(Fabs(x - {0.5 * CHORD}) - {0.5 * CHORD})) / 2"
        dy = f"((y - {SEMISPAN}) + Fabs(y - {SEMISPAN})) / 2"
        dist = f"Sqrt(({dx})^2 + ({dy})^2 + z^2)"
        f = gmsh.model.mesh.field
        m = f.add("MathEval")
        f.setString(m, "F", f"{size_near} + {size_growth} * {dist}")
        t = f.add("Min")
        c_far = f.add("Constant")
        f.setNumber(c_far, "VIn", h_far)
        f.setNumbers(t, "FieldsList", [m, c_far])
        f.setAsBackgroundMesh(t)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 1)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.model.mesh.generate(3)
        node_tags, xyz = gmsh.model.mesh.getNodes()[:2]
        etypes, _, enodes = gmsh.model.mesh.getElements(3, vol)
        if list(etypes) != [4]:
            raise RuntimeError(f"{name}: gmsh made elements {list(etypes)}, expected linear tetrahedra")
        faces = {"symmetry": [sym], "farfield": far}
        marker_tags = {}
        for g, tags in faces.items():
            parts = []
            for s in tags:
                et, _, en = gmsh.model.mesh.getElements(2, s)
                parts.append(en[0].reshape(-1, 3).astype(np.int64))
            marker_tags[g] = np.concatenate(parts)
    finally:
        gmsh.finalize()
    node_tags = node_tags.astype(np.int64)
    xyz = xyz.reshape(-1, 3)
    tets_tags = enodes[0].reshape(-1, 4).astype(np.int64)
    # gmsh renumbers the nodes when it meshes: the top's nodes are found again by their coordinates
    # (gmsh keeps a discrete surface's nodes where they were given)
    dist, near = cKDTree(top).query(xyz)
    is_top = dist <= 1e-12 * float(np.ptp(top, axis=0).max())
    if np.count_nonzero(is_top) != k_top or len(np.unique(near[is_top])) != k_top:
        raise RuntimeError(f"{name}: gmsh did not keep the {k_top} nodes of the prism layers' top")
    lookup = np.full(int(node_tags.max()) + 1, -1, dtype=np.int64)
    lookup[node_tags[is_top]] = near[is_top]
    new = node_tags[~is_top]
    used_new = np.intersect1d(new, tets_tags.ravel())
    lookup[used_new] = k_top + np.arange(len(used_new))
    pos = np.full(len(lookup), -1, dtype=np.int64)
    pos[node_tags] = np.arange(len(node_tags))
    points = np.concatenate([top, xyz[pos[used_new]]])
    tets = lookup[tets_tags]
    markers = {g: lookup[t] for g, t in marker_tags.items()}
    if np.any(tets < 0) or any(np.any(t < 0) for t in markers.values()):
        raise RuntimeError(f"{name}: gmsh's cells reference a node it did not return")
    vol_t = tet_volumes(points, tets)
    tets[vol_t < 0] = tets[vol_t < 0][:, [0, 2, 1, 3]]
    points[markers["symmetry"].ravel(), 1] = lo[1]
    return points, tets, orient_out_of_fluid(points, tets, markers)


def hybrid_mesh(level: HybridLevel, farfield: float = 25.0) -> Mesh:
    """The level's mesh (module docstring); raises RuntimeError on a cell of quality <= 0."""
    wall, tris, ids = wing_surface(level)
    nw = len(wall)
    pts, wedges, quads = prism_layers(wall, tris, ids, level)
    top0 = level.layers * nw
    top = pts[top0:]
    lo, hi = box(farfield)
    tp, tets, mk = outer_tets(top, tris, ids["root"], lo, hi, level.h_near, 0.25, level.h_far,
                              f"adodg3_{level.name}")
    # gmsh's points: the first nw are the top layer's (unchanged), the rest are appended
    points = np.concatenate([pts, tp[nw:]])
    remap = np.concatenate([top0 + np.arange(nw), len(pts) + np.arange(len(tp) - nw)])
    tets = remap[tets]
    mesh = Mesh(points=points, dim=3,
                cells=[CellBlock("tetra", tets), CellBlock("wedge", wedges)],
                markers={"wing": [CellBlock("triangle", tris[:, [0, 2, 1]])],
                         "symmetry": [CellBlock("triangle", remap[mk["symmetry"]]), CellBlock("quad", quads)],
                         "farfield": [CellBlock("triangle", remap[mk["farfield"]])]})
    q = cell_quality(mesh.points, mesh.cells)
    if q.min() <= 0:
        raise RuntimeError(f"{level.name}: {int(np.sum(q <= 0))} cells of quality <= 0")
    return mesh


#: Element-size ratio between consecutive levels.
RATIO = 2.0 ** 0.5


#: The prism layers' total height (chords): the structured part reaches this far from the wall on
#: every level (the flow round the leading edge, whose pressure the drag is so sensitive to, lies in it).
LAYERS_HEIGHT = 0.4


def layer_growth(first: float, layers: int, total: float) -> float:
    """The growth ratio g with ``first (g^layers - 1) / (g - 1) = total``."""
    return float(brentq(lambda g: first * (g ** layers - 1.0) / (g - 1.0) - total, 1.0 + 1e-9, 4.0))


def hybrid_levels() -> list[HybridLevel]:
    """H0 (coarsest) ... H2: every wall spacing of H0 divided by :data:`RATIO` per level; 12, 14, 16
    layers from a first height of 0.0016 chord (divided by RATIO per level) to :data:`LAYERS_HEIGHT`
    (the growth solved for), the tetrahedra starting at the top layer's height. H0's leading-edge
    spacing is a tenth of the leading-edge radius."""
    out = []
    for i in range(3):
        f = RATIO ** -i
        first, layers = 0.0016 * f, 12 + 2 * i
        g = layer_growth(first, layers, LAYERS_HEIGHT)
        out.append(HybridLevel(f"H{i}", ds_le=0.1 * LE_RADIUS * f, ds_te=0.004 * f, ds_max=0.06 * f,
                               dy_max=0.15 * f, dy_tip=0.03 * f, growth=1.2, first=first, layers=layers,
                               layer_growth=g, h_near=first * g ** (layers - 1), h_far=15.0 * f))
    return out
