"""Regenerate the bundled sample meshes and airfoil files of ``samples/``.

Usage (from the repository root; needs the optional extra ``samples``, i.e. gmsh)::

    PYTHONPATH=$PWD python samples/make_samples.py            # all samples
    PYTHONPATH=$PWD python samples/make_samples.py rect_wing  # one of them

The outputs are committed, so neither the tests nor CI need gmsh. The 3D wings are lofted with the
OpenCASCADE kernel through NACA sections from :mod:`ffdcli.testing.wings` (same planform parameters as
``rect_wing_planform`` / ``crm_planform``), cut from a box far field and meshed with tetrahedra; the 2D
O-grid is :func:`ffdcli.testing.wings.airfoil_ogrid` (pure NumPy). The SU2 files are written by the small
writer below (``ffdcli.io.formats.su2`` is not used so that this script stays independent of it).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from ffdcli.io.atomic import atomic_write  # noqa: E402
from ffdcli.mesh import VTK_ID  # noqa: E402
from ffdcli.testing import wings  # noqa: E402

# ----------------------------------------------------------------------------------------------
# A minimal SU2 writer and checks
# ----------------------------------------------------------------------------------------------


def write_su2(path: Path, ndime: int, points: np.ndarray, cells: list[tuple[str, np.ndarray]],
              markers: dict[str, list[tuple[str, np.ndarray]]]) -> None:
    """Write an SU2 ASCII mesh: NDIME, NELEM (VTK ids, 0-based nodes, element index), NPOIN, NMARK."""
    lines = [f"NDIME= {ndime}"]
    n_elem = sum(len(c) for _, c in cells)
    lines.append(f"NELEM= {n_elem}")
    k = 0
    for kind, conn in cells:
        for row in conn:
            lines.append(f"{VTK_ID[kind]} " + " ".join(map(str, row)) + f" {k}")
            k += 1
    lines.append(f"NPOIN= {len(points)}")
    for i, p in enumerate(points[:, :ndime]):
        lines.append(" ".join(f"{v:.15g}" for v in p) + f" {i}")
    lines.append(f"NMARK= {len(markers)}")
    for name, blocks in markers.items():
        lines.append(f"MARKER_TAG= {name}")
        lines.append(f"MARKER_ELEMS= {sum(len(c) for _, c in blocks)}")
        for kind, conn in blocks:
            for row in conn:
                lines.append(f"{VTK_ID[kind]} " + " ".join(map(str, row)))
    with atomic_write(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def tet_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes of VTK-ordered tetrahedra (positive: p3 on the side of the normal of p0 p1 p2)."""
    p = points[tets]
    return np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6.0


# ----------------------------------------------------------------------------------------------
# 3D wings with gmsh
# ----------------------------------------------------------------------------------------------


def mesh_wing(planform: wings.Planform, *, etas, box_lo, box_hi, h_wing: float, h_edge: float,
              h_far: float, n_chord: int = 81, ruled: bool = True):
    """Tetrahedral mesh of the fluid between a lofted wing and a box; returns points, tets, markers.

    The wing is a loft (``ruled``: straight between consecutive sections) through the planform's
    sections at ``etas``, closed by a flat tip cap; its root section lies in the box face at span 0
    (the symmetry plane). Sizes: ``h_wing`` on the wing, ``h_edge`` near the leading and trailing
    edges and the tip, growing to ``h_far`` at the box.
    """
    import gmsh

    gmsh.initialize(["-nt", "1"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("wing")
        occ = gmsh.model.occ
        etas = np.asarray(etas, dtype=float)
        coords = planform.airfoil_coords(etas, 2 * n_chord - 1)
        wires = []
        for j, eta in enumerate(etas):
            xyz = planform.section_points(np.array([eta]), coords[j])[0]
            le = n_chord - 1
            tags = [occ.addPoint(*p) for p in xyz[:-1]]        # sharp TE: last point == first
            tags.append(tags[0])
            upper = occ.addSpline(tags[: le + 1])
            lower = occ.addSpline(tags[le:])
            wires.append(occ.addWire([upper, lower]))
        wing = occ.addThruSections(wires, makeSolid=True, makeRuled=ruled)
        lo, hi = np.asarray(box_lo, float), np.asarray(box_hi, float)
        box = occ.addBox(*lo, *(hi - lo))
        fluid, _ = occ.cut([(3, box)], wing)
        occ.synchronize()
        vols = gmsh.model.getEntities(3)
        assert len(vols) == 1, vols
        span_axis = planform.axes[2]
        root_plane = planform.root_offset[span_axis]
        groups = {"wing": [], "symmetry": [], "farfield": []}
        tol = 1e-6 * float(np.max(hi - lo))
        for dim, tag in gmsh.model.getBoundary(vols, oriented=False):
            bb = np.array(gmsh.model.getBoundingBox(dim, tag)).reshape(2, 3)
            flat = np.abs(bb[0] - bb[1]) < tol
            on_face = (np.abs(bb[0] - lo) < tol) | (np.abs(bb[0] - hi) < tol)
            on_box = [ax for ax in range(3) if flat[ax] and on_face[ax]]
            if on_box and on_box[0] == span_axis and abs(bb[0, span_axis] - root_plane) < tol:
                groups["symmetry"].append(tag)
            elif on_box:
                groups["farfield"].append(tag)
            else:
                groups["wing"].append(tag)
        for name, tags in groups.items():
            assert tags, f"no surface classified as {name}"
            gmsh.model.addPhysicalGroup(2, tags, name=name)
        gmsh.model.addPhysicalGroup(3, [vols[0][1]], name="fluid")

        # sizes: fine on the wing, finer at its edges (curves of the wing), growing to the box
        wing_curves = sorted({abs(c[1]) for s in groups["wing"]
                              for c in gmsh.model.getBoundary([(2, s)], oriented=False)})
        f = gmsh.model.mesh.field
        d_s = f.add("Distance")
        f.setNumbers(d_s, "SurfacesList", groups["wing"])
        f.setNumber(d_s, "Sampling", 60)
        t_s = f.add("Threshold")
        f.setNumber(t_s, "InField", d_s)
        f.setNumber(t_s, "SizeMin", h_wing)
        f.setNumber(t_s, "SizeMax", h_far)
        f.setNumber(t_s, "DistMin", 0.5 * h_wing)
        f.setNumber(t_s, "DistMax", 0.6 * float(np.min(hi - lo)))
        d_c = f.add("Distance")
        f.setNumbers(d_c, "CurvesList", wing_curves)
        f.setNumber(d_c, "Sampling", 200)
        t_c = f.add("Threshold")
        f.setNumber(t_c, "InField", d_c)
        f.setNumber(t_c, "SizeMin", h_edge)
        f.setNumber(t_c, "SizeMax", h_far)
        f.setNumber(t_c, "DistMin", 0.5 * h_edge)
        f.setNumber(t_c, "DistMax", 20 * h_wing)
        m = f.add("Min")
        f.setNumbers(m, "FieldsList", [t_s, t_c])
        f.setAsBackgroundMesh(m)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.model.mesh.generate(3)

        node_tags, xyz, _ = gmsh.model.mesh.getNodes()
        xyz = xyz.reshape(-1, 3)
        etypes, _, enodes = gmsh.model.mesh.getElements(3, vols[0][1])
        assert list(etypes) == [4], etypes                    # linear tetrahedra only
        tets_tags = enodes[0].reshape(-1, 4).astype(np.int64)
        marker_tags = {}
        for name, tags in groups.items():
            tris = []
            for s in tags:
                et, _, en = gmsh.model.mesh.getElements(2, s)
                assert list(et) == [2], et
                tris.append(en[0].reshape(-1, 3).astype(np.int64))
            marker_tags[name] = np.concatenate(tris)
    finally:
        gmsh.finalize()

    # compact 0-based numbering of the nodes the tetrahedra use
    used = np.unique(tets_tags)
    lookup = np.full(int(max(node_tags.max(), used.max())) + 1, -1, dtype=np.int64)
    lookup[used] = np.arange(len(used))
    pos = np.full(len(lookup), -1, dtype=np.int64)
    pos[node_tags.astype(np.int64)] = np.arange(len(node_tags))
    points = xyz[pos[used]]
    tets = lookup[tets_tags]
    vol = tet_volumes(points, tets)
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]              # VTK/SU2 orientation: all positive
    markers = {}
    for name, tris in marker_tags.items():
        t = lookup[tris]
        if np.any(t < 0):
            raise RuntimeError(f"marker {name} references a node that no tetrahedron uses")
        markers[name] = t
    markers = _orient_boundary(points, tets, markers)
    return points, tets, markers


def _orient_boundary(points, tets, markers):
    """Orient each boundary triangle with its normal out of the fluid (away from its tetrahedron)."""
    faces = np.sort(np.concatenate([tets[:, [0, 1, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 3]],
                                    tets[:, [1, 2, 3]]]), axis=1)
    opposite = np.concatenate([tets[:, 3], tets[:, 2], tets[:, 1], tets[:, 0]])
    key = (faces[:, 0] * len(points) + faces[:, 1]) * len(points) + faces[:, 2]
    order = np.argsort(key)
    key_sorted = key[order]
    out = {}
    for name, tris in markers.items():
        s = np.sort(tris, axis=1)
        k = (s[:, 0] * len(points) + s[:, 1]) * len(points) + s[:, 2]
        i = np.searchsorted(key_sorted, k)
        if np.any(i >= len(key_sorted)) or np.any(key_sorted[np.minimum(i, len(key_sorted) - 1)] != k):
            raise RuntimeError(f"marker {name} has a triangle that is not a tetrahedron face")
        opp = points[opposite[order[i]]]
        p = points[tris]
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        inward = np.einsum("ij,ij->i", n, opp - p[:, 0]) > 0
        t = tris.copy()
        t[inward] = t[inward][:, [0, 2, 1]]
        out[name] = t
    return out


def make_rect_wing(out: Path) -> dict:
    pf = wings.rect_wing_planform()                    # NACA 0012, chord 1 x, thickness y, span z 0..3
    pts, tets, markers = mesh_wing(pf, etas=[0.0, 1.0], box_lo=(-10.0, -10.0, 0.0), box_hi=(11.0, 10.0, 13.0),
                                   h_wing=0.035, h_edge=0.015, h_far=2.0)
    write_su2(out, 3, pts, [("tetra", tets)], {k: [("triangle", v)] for k, v in markers.items()})
    return summary(out, pts, tets, markers)


def make_crm_wing(out: Path) -> dict:
    pf = wings.crm_planform(semi_span=3.0, root_chord=1.0, kink_te_extension=0.37)
    etas = [0.0, pf.kink_eta, 1.0]
    c = pf.root_chord
    pts, tets, markers = mesh_wing(pf, etas=etas, box_lo=(-10 * c, 0.0, -10 * c),
                                   box_hi=(13 * c, 3.0 + 10 * c, 10 * c),
                                   h_wing=0.03, h_edge=0.01, h_far=2.0)
    write_su2(out, 3, pts, [("tetra", tets)], {k: [("triangle", v)] for k, v in markers.items()})
    return summary(out, pts, tets, markers)


# ----------------------------------------------------------------------------------------------
# Several components: wing + horizontal tail + fin, and a wing on a fuselage (issue 16)
# ----------------------------------------------------------------------------------------------


def _loft(occ, planform: wings.Planform, etas, n_chord: int = 61) -> int:
    """OCC solid lofted straight through the planform's sections at ``etas`` (sharp TE, flat caps)."""
    coords = planform.airfoil_coords(np.asarray(etas, float), 2 * n_chord - 1)
    wires = []
    for j, eta in enumerate(etas):
        xyz = planform.section_points(np.array([eta]), coords[j])[0]
        le = n_chord - 1
        tags = [occ.addPoint(*p) for p in xyz[:-1]]
        tags.append(tags[0])
        wires.append(occ.addWire([occ.addSpline(tags[: le + 1]), occ.addSpline(tags[le:])]))
    return occ.addThruSections(wires, makeSolid=True, makeRuled=True)[0][1]


def mesh_parts(builders: dict, *, box_lo, box_hi, symmetry_axis: int, h_part: float, h_edge: float,
               h_far: float, fuse: bool = False):
    """Tetrahedral mesh of the fluid between several solids and a box; markers named after the solids.

    ``builders`` maps a marker name to ``f(occ) -> volume tag``. ``fuse``: the solids intersect (a
    wing on a fuselage) and are fused first, so that they share the junction curve. Every boundary
    face of the fluid goes to ``symmetry`` (the box face at ``symmetry_axis`` = 0), ``farfield`` (the
    other box faces) or to the solid whose bounding box holds it (the smallest such box).
    """
    import gmsh

    gmsh.initialize(["-nt", "1"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add("parts")
        occ = gmsh.model.occ
        solids = {name: build(occ) for name, build in builders.items()}
        occ.synchronize()
        bbs = {name: np.array(gmsh.model.getBoundingBox(3, t)).reshape(2, 3) for name, t in solids.items()}
        lo, hi = np.asarray(box_lo, float), np.asarray(box_hi, float)
        tools = [(3, t) for t in solids.values()]
        if fuse:
            tools, _ = occ.fuse(tools[:1], tools[1:])
        box = occ.addBox(*lo, *(hi - lo))
        occ.cut([(3, box)], tools)
        occ.synchronize()
        vols = gmsh.model.getEntities(3)
        assert len(vols) == 1, vols
        groups = {name: [] for name in solids}
        groups.update(symmetry=[], farfield=[])
        tol = 1e-6 * float(np.max(hi - lo))
        for dim, tag in gmsh.model.getBoundary(vols, oriented=False):
            bb = np.array(gmsh.model.getBoundingBox(dim, tag)).reshape(2, 3)
            flat = np.abs(bb[0] - bb[1]) < tol
            on_face = (np.abs(bb[0] - lo) < tol) | (np.abs(bb[0] - hi) < tol)
            on_box = [ax for ax in range(3) if flat[ax] and on_face[ax]]
            if on_box and on_box[0] == symmetry_axis and abs(bb[0, symmetry_axis]) < tol:
                groups["symmetry"].append(tag)
            elif on_box:
                groups["farfield"].append(tag)
            else:
                holders = [n for n, b in bbs.items() if np.all(bb[0] >= b[0] - 1e-3) and np.all(bb[1] <= b[1] + 1e-3)]
                assert holders, f"face {tag} {bb.tolist()} is in no solid's bounding box"
                groups[min(holders, key=lambda n: float(np.prod(np.ptp(bbs[n], axis=0))))].append(tag)
        part_faces = [t for n in solids for t in groups[n]]
        for name, tags in groups.items():
            assert tags, f"no surface classified as {name}"
            gmsh.model.addPhysicalGroup(2, tags, name=name)
        curves = sorted({abs(c[1]) for s in part_faces for c in gmsh.model.getBoundary([(2, s)], oriented=False)})
        f = gmsh.model.mesh.field
        d_s = f.add("Distance")
        f.setNumbers(d_s, "SurfacesList", part_faces)
        f.setNumber(d_s, "Sampling", 60)
        t_s = f.add("Threshold")
        f.setNumber(t_s, "InField", d_s)
        f.setNumber(t_s, "SizeMin", h_part)
        f.setNumber(t_s, "SizeMax", h_far)
        f.setNumber(t_s, "DistMin", 0.5 * h_part)
        f.setNumber(t_s, "DistMax", 0.6 * float(np.min(hi - lo)))
        d_c = f.add("Distance")
        f.setNumbers(d_c, "CurvesList", curves)
        f.setNumber(d_c, "Sampling", 200)
        t_c = f.add("Threshold")
        f.setNumber(t_c, "InField", d_c)
        f.setNumber(t_c, "SizeMin", h_edge)
        f.setNumber(t_c, "SizeMax", h_far)
        f.setNumber(t_c, "DistMin", 0.5 * h_edge)
        f.setNumber(t_c, "DistMax", 20 * h_part)
        m = f.add("Min")
        f.setNumbers(m, "FieldsList", [t_s, t_c])
        f.setAsBackgroundMesh(m)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.model.mesh.generate(3)
        node_tags, xyz, _ = gmsh.model.mesh.getNodes()
        xyz = xyz.reshape(-1, 3)
        etypes, _, enodes = gmsh.model.mesh.getElements(3, vols[0][1])
        assert list(etypes) == [4], etypes
        tets_tags = enodes[0].reshape(-1, 4).astype(np.int64)
        marker_tags = {}
        for name, tags in groups.items():
            tris = []
            for s in tags:
                et, _, en = gmsh.model.mesh.getElements(2, s)
                assert list(et) == [2], et
                tris.append(en[0].reshape(-1, 3).astype(np.int64))
            marker_tags[name] = np.concatenate(tris)
    finally:
        gmsh.finalize()
    used = np.unique(tets_tags)
    lookup = np.full(int(max(node_tags.max(), used.max())) + 1, -1, dtype=np.int64)
    lookup[used] = np.arange(len(used))
    pos = np.full(len(lookup), -1, dtype=np.int64)
    pos[node_tags.astype(np.int64)] = np.arange(len(node_tags))
    points = xyz[pos[used]]
    tets = lookup[tets_tags]
    vol = tet_volumes(points, tets)
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]
    markers = {}
    for name, tris in marker_tags.items():
        t = lookup[tris]
        if np.any(t < 0):
            raise RuntimeError(f"marker {name} references a node that no tetrahedron uses")
        markers[name] = t
    return points, tets, _orient_boundary(points, tets, markers)


# Chord x, span y, thickness z (as the CRM); the symmetry plane is y = 0.
WING = dict(semi_span=2.5, root_chord=1.0, taper=0.4, le_sweep_deg=25.0, root_airfoil="0012", sections="xz")
HTAIL = dict(semi_span=1.0, root_chord=0.5, taper=0.6, le_sweep_deg=30.0, root_airfoil="0010", sections="xz",
             root_offset=(3.0, 0.0, 0.0))
# a twin fin standing clear above the tail (its root at z = 0.3): span along z
FIN = dict(semi_span=0.7, root_chord=0.5, taper=0.6, le_sweep_deg=35.0, root_airfoil="0010", sections="xy",
           root_offset=(3.1, 0.6, 0.3))
FUSELAGE_RADIUS = 0.35


def make_wing_tail_fin(out: Path) -> dict:
    """Wing + horizontal tail (roots on the symmetry plane) + a vertical fin (span along z)."""
    parts = {"wing": (WING, [0.0, 1.0]), "htail": (HTAIL, [0.0, 1.0]), "vfin": (FIN, [0.0, 1.0])}
    builders = {n: (lambda occ, kw=kw, e=e: _loft(occ, wings.Planform(**kw), e)) for n, (kw, e) in parts.items()}
    pts, tets, markers = mesh_parts(builders, box_lo=(-6.0, 0.0, -6.0), box_hi=(10.0, 7.0, 6.0), symmetry_axis=1,
                                    h_part=0.045, h_edge=0.018, h_far=2.0)
    write_su2(out, 3, pts, [("tetra", tets)], {k: [("triangle", v)] for k, v in markers.items()})
    return summary(out, pts, tets, markers)


def _fuselage(occ) -> int:
    """Half a body of revolution along x (the box cuts it at y = 0): a cylinder with a round nose and tail."""
    r = FUSELAGE_RADIUS
    cyl = occ.addCylinder(-0.5, 0.0, 0.0, 3.5, 0.0, 0.0, r)
    nose = occ.addSphere(-0.5, 0.0, 0.0, r)
    tail = occ.addSphere(3.0, 0.0, 0.0, r)
    (out, _) = occ.fuse([(3, cyl)], [(3, nose), (3, tail)])
    return out[0][1]


def make_wing_body(out: Path) -> dict:
    """A low wing through a fuselage: the wing's root meets the fuselage, not the symmetry plane."""
    wing = wings.Planform(**{**WING, "root_offset": (0.6, 0.0, -0.12)})
    builders = {"fuselage": _fuselage, "wing": lambda occ: _loft(occ, wing, [0.0, 1.0])}
    pts, tets, markers = mesh_parts(builders, box_lo=(-6.0, 0.0, -6.0), box_hi=(10.0, 7.0, 6.0), symmetry_axis=1,
                                    h_part=0.045, h_edge=0.018, h_far=2.0, fuse=True)
    write_su2(out, 3, pts, [("tetra", tets)], {k: [("triangle", v)] for k, v in markers.items()})
    return summary(out, pts, tets, markers)


def make_naca0012_2d(out: Path) -> dict:
    m = wings.airfoil_ogrid_mesh("0012", n_around=161, n_radial=41, farfield_radius=15.0)
    write_su2(out, 2, m.points, [("quad", m.cells[0].data)],
              {k: [("line", b[0].data)] for k, b in m.markers.items()})
    q = m.cells[0].data
    return {"file": out.name, "points": m.n_points, "quad": len(q),
            "markers": {k: len(b[0]) for k, b in m.markers.items()},
            "min_area": float(wings.quad_areas(m.points, q).min())}


def summary(out, pts, tets, markers) -> dict:
    return {"file": out.name, "points": len(pts), "tetra": len(tets),
            "markers": {k: len(v) for k, v in markers.items()},
            "min_volume": float(tet_volumes(pts, tets).min()), "bytes": out.stat().st_size}


def write_dat(out: Path, name: str, coords: np.ndarray) -> None:
    out.write_text(name + "\n" + "".join(f"{x:10.7f} {y:10.7f}\n" for x, y in coords))


def make_airfoils() -> list[dict]:
    naca = wings.naca4("0012", 133, closed_te=True)
    write_dat(HERE / "naca0012.dat", "NACA 0012 (closed trailing edge, cosine spacing, ffdcli.testing.wings.naca4)",
              naca)
    src = Path("/work/shared/data/airfoils/s1223.dat")
    if src.exists():
        (HERE / "s1223.dat").write_bytes(src.read_bytes())
    return [{"file": "naca0012.dat", "points": len(naca)}]


def make_volume_sens(out: Path) -> dict:
    """dJ/dX of J = the enclosed volume of ``rect_wing.su2``'s wing, in SU2's ``surface_sens.csv`` layout.

    Not an adjoint solution: a sensitivity of a functional known in closed form, the oracle of
    ``ffd grad``'s test (``configs/rect_grad.yaml``; written to ``out/``, not shipped: the bundled
    sensitivity is SU2's real drag adjoint, :func:`make_su2_drag_sens`). The volume and its exact
    gradient are those of ffd's ``volume`` constraint (:class:`ffdcli.constraints.geometric.Volume`:
    the half wing closed by its symmetry plane z = 0).
    The marker's triangles face into the wing (out of the fluid), hence the sign.
    """
    from ffdcli.constraints.geometric import Volume, surface_triangles
    from ffdcli.geometry.surface import extract_surface
    from ffdcli.io.formats import read_mesh

    out.parent.mkdir(parents=True, exist_ok=True)

    m = read_mesh(HERE / "rect_wing.su2")
    surf = extract_surface(m, ["wing"])
    vol = Volume(index=0, lower=None, upper=None, cells=surface_triangles(surf.faces),
                 origin=np.zeros(3), base=1.0, dim=3)
    volume, g = vol.measure(surf.points, grad=True)
    sign = np.sign(volume)
    rows = np.column_stack([surf.ids, surf.points, sign * g])
    header = '"PointID","x","y","z","Sensitivity_x","Sensitivity_y","Sensitivity_z"'
    with atomic_write(out, "w") as fh:
        fh.write(header + "\n")
        np.savetxt(fh, rows, fmt=["%d"] + ["%.12e"] * 6, delimiter=",")
    return {"file": out.name, "rows": len(surf.ids), "volume": abs(volume)}


def su2_programs() -> Path | None:
    """The folder of SU2's programs: ``SU2_RUN``, the ``PATH``, then ``../shared/su2/bin`` beside the
    repository; None when SU2 is not installed."""
    import os
    import shutil

    cands = [Path(os.environ["SU2_RUN"])] if os.environ.get("SU2_RUN") else []
    if shutil.which("SU2_CFD"):
        cands.append(Path(shutil.which("SU2_CFD")).resolve().parent)
    cands.append(HERE.parent.parent / "shared" / "su2" / "bin")
    return next((c for c in cands if (c / "SU2_CFD").is_file()), None)


def make_su2_drag_sens(out: Path) -> dict:
    """dJ/dX of the drag of ``naca0012_2d.su2`` at every node, by SU2's discrete adjoint.

    Flow: SU2_CFD with ``naca0012_2d_euler.cfg`` (Euler, M 0.8, alpha 1.25 deg, residuals to 1e-12);
    adjoint: SU2_CFD_AD with ``MATH_PROBLEM= DISCRETE_ADJOINT``, ``OBJECTIVE_FUNCTION= DRAG`` on that
    flow (its ``restart_flow.dat`` copied to ``solution_flow.dat``). Of SU2's ``restart_adj_cd.csv``
    (every node: adjoint variables and ``Sensitivity_x/y``) the file keeps the point id, coordinates
    and sensitivities, 13 significant digits. Needs SU2 (``SU2_RUN``, ``PATH`` or ``../shared/su2/bin``).
    """
    import shutil
    import subprocess
    import tempfile

    bindir = su2_programs()
    if bindir is None or not (bindir / "SU2_CFD_AD").is_file():
        raise SystemExit("SU2_CFD and SU2_CFD_AD are needed (SU2_RUN, PATH or ../shared/su2/bin)")
    cfg = (HERE / "naca0012_2d_euler.cfg").read_text()
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        shutil.copyfile(HERE / "naca0012_2d.su2", t / "naca0012_2d.su2")
        (t / "flow.cfg").write_text(cfg)
        (t / "adj.cfg").write_text(cfg.replace("MATH_PROBLEM= DIRECT", "MATH_PROBLEM= DISCRETE_ADJOINT"))
        for prog, conf in (("SU2_CFD", "flow.cfg"), ("SU2_CFD_AD", "adj.cfg")):
            with open(t / f"{prog}.log", "w") as log:
                rc = subprocess.run([str(bindir / prog), conf], cwd=t, stdout=log, stderr=subprocess.STDOUT).returncode
            if rc != 0:
                raise SystemExit(f"{prog} failed ({rc}): {(t / f'{prog}.log').read_text()[-2000:]}")
            if prog == "SU2_CFD":
                shutil.copyfile(t / "restart_flow.dat", t / "solution_flow.dat")
                flow = (t / "history.csv").read_text().splitlines()
        head = [h.strip().strip('"') for h in (t / "restart_adj_cd.csv").open().readline().split(",")]
        data = np.loadtxt(t / "restart_adj_cd.csv", delimiter=",", skiprows=1, ndmin=2)
    cols = [head.index(c) for c in ("PointID", "x", "y", "Sensitivity_x", "Sensitivity_y")]
    rows = data[:, cols]
    with atomic_write(out, "w") as fh:
        fh.write('"PointID","x","y","Sensitivity_x","Sensitivity_y"\n')
        np.savetxt(fh, rows, fmt=["%d"] + ["%.12e"] * 4, delimiter=",")
    hh = [h.strip().strip('"') for h in flow[0].split(",")]
    last = dict(zip(hh, flow[-1].split(",")))
    return {"file": out.name, "rows": len(rows), "CD": float(last["CD"]), "CL": float(last["CL"]),
            "iterations": int(float(last["Inner_Iter"])), "rms[Rho]": float(last["rms[Rho]"])}


MAKERS = {
    "naca0012_2d": lambda: make_naca0012_2d(HERE / "naca0012_2d.su2"),
    "rect_wing": lambda: make_rect_wing(HERE / "rect_wing.su2"),
    "crm_wing": lambda: make_crm_wing(HERE / "crm_wing.su2"),
    "airfoils": make_airfoils,
    "surface_sens": lambda: make_volume_sens(HERE.parent / "out" / "rect_wing_volume_sens.csv"),
    "naca0012_2d_sens": lambda: make_su2_drag_sens(HERE / "naca0012_2d_cd_sens.csv"),
    "wing_tail_fin": lambda: make_wing_tail_fin(HERE / "wing_tail_fin.su2"),
    "wing_body": lambda: make_wing_body(HERE / "wing_body.su2"),
}


NEEDS_SU2 = ("naca0012_2d_sens",)


if __name__ == "__main__":
    for name in sys.argv[1:] or list(MAKERS):
        if name in NEEDS_SU2 and su2_programs() is None:
            print(name, "skipped: SU2 is not installed (SU2_RUN, PATH or ../shared/su2/bin)", flush=True)
            continue
        print(name, MAKERS[name](), flush=True)
