"""The one gmsh generator of tetrahedral wing meshes: the bundled samples, the tests, the robustness benchmark.

Two levels:

- :func:`fluid_tets` meshes the fluid between one or more solids and a box with gmsh tetrahedra
  (OpenCASCADE kernel, one thread). The solids are lofts through wing sections (:func:`loft`,
  straight between consecutive sections, sharp or blunt trailing edge, flat end caps) or any
  OpenCASCADE solid (a fuselage); several solids may be fused first (a wing through a fuselage).
  Markers: the box face at ``symmetry_at`` on the ``symmetry_axis`` is ``symmetry``, the other box
  faces ``farfield``, every other face belongs to the solid whose bounding box holds it (marker named
  after the solid). Sizes: ``h_solid`` on the solids, ``h_edge`` near their edges (leading and
  trailing edges, tips, junctions), growing to ``h_far`` at the box. ``samples/make_samples.py``
  makes the bundled meshes with it.
- :class:`WingCase` and :func:`wing_volume_mesh`: a half wing of a :class:`~ffdcli.testing.planform.Planform`
  whose root lies in the symmetry plane and whose TIP IS INSIDE THE DOMAIN (the far-field box extends
  beyond it), as in a real external-aerodynamics mesh: any span axis (x, y or z), left or right
  (``span_sign``), sweep, dihedral, taper, twist, a trailing-edge kink, sharp or blunt trailing edge;
  the tip ``flat`` (the tip section closed by a plane) or ``round`` (the thickness shrinks as
  ``cos(phi)`` over half a tip thickness beyond the tip, a faceted half-round cap); the far field at
  ``farfield`` root chords from the wing on every side but the root plane; ``layers`` > 0 adds thin
  boundary-layer prisms on the wing (:func:`ffdcli.testing.prisms.add_prism_layers`). Markers
  ``wing``, ``symmetry``, ``farfield``. :data:`CASES` names a set with variety (the robustness
  benchmark, ``benchmarks/bench_robustness.py``, deforms every one); :func:`write_case` writes one
  as SU2, cached by the hash of its parameters.

The cells are in VTK order with positive volume and the boundary triangles face out of the fluid. A
generated mesh with a cell of quality <= 0 (:func:`ffdcli.quality.metrics.cell_quality`) is an error.
gmsh (the ``[test]`` or ``[samples]`` extra) is imported only inside :func:`fluid_tets`, so this module
and its cases import without it.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from ffdcli.io.formats import write_mesh
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.mesh.idsets import unique_ids
from ffdcli.quality.metrics import cell_quality
from ffdcli.testing.cells import tet_volumes
from ffdcli.testing.planform import Planform, crm_planform
from ffdcli.testing.prisms import add_prism_layers

#: Bump when the generator changes what it writes (part of the cache key).
GENERATOR_VERSION = 2

#: A solid of :func:`fluid_tets`: ``build(occ) -> volume tag`` with ``occ`` = ``gmsh.model.occ``.
SolidBuilder = Callable[[object], int]


# ----------------------------------------------------------------------------------------------
# The generator (gmsh)
# ----------------------------------------------------------------------------------------------

def planform_sections(planform: Planform, etas, n_chord: int) -> list[np.ndarray]:
    """Mesh coordinates (2 n_chord - 1, 3) of the planform's sections at stations ``etas``, root -> tip."""
    etas = np.asarray(etas, dtype=float)
    coords = planform.airfoil_coords(etas, 2 * n_chord - 1)
    return [planform.section_points(np.array([e]), coords[j])[0] for j, e in enumerate(etas)]


def loft(occ, sections: list[np.ndarray]) -> int:
    """An OpenCASCADE solid lofted straight through ``sections`` (flat end caps); its volume tag.

    Each section is (2 n_chord - 1, 3) points in Selig order (trailing edge, upper side, leading edge
    at point n_chord - 1, lower side); a sharp trailing edge repeats its first point last, a blunt
    one is closed by a straight line. Each side is one cubic spline.
    """
    wires = []
    for xyz in sections:
        le = (len(xyz) - 1) // 2
        scale = float(np.max(np.ptp(xyz, axis=0)))
        closed = np.allclose(xyz[0], xyz[-1], rtol=0.0, atol=1e-12 * scale)
        tags = [occ.addPoint(*p) for p in (xyz[:-1] if closed else xyz)]
        if closed:
            tags.append(tags[0])
        curves = [occ.addSpline(tags[: le + 1]), occ.addSpline(tags[le:])]
        if not closed:
            curves.append(occ.addLine(tags[-1], tags[0]))
        wires.append(occ.addWire(curves))
    out = occ.addThruSections(wires, makeSolid=True, makeRuled=True)
    if len(out) != 1:
        raise RuntimeError(f"the loft made {len(out)} entities, expected one solid")
    return out[0][1]


def fluid_tets(solids: dict[str, SolidBuilder], lo, hi, *, symmetry_axis: int, symmetry_at: float = 0.0,
               h_solid: float, h_edge: float, h_far: float, grow: float | None = None, fuse: bool = False,
               name: str = "fluid", edge_grow: float | None = None
               ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Tetrahedral mesh of the fluid between ``solids`` and the box ``lo``..``hi`` (module docstring).

    Parameters
    ----------
    solids
        Marker name -> builder of the solid (:data:`SolidBuilder`, e.g. ``partial(loft, sections=...)``).
    lo, hi
        (3,) corners of the far-field box.
    symmetry_axis, symmetry_at
        The box face at coordinate ``symmetry_at`` along this axis is the marker ``symmetry``; its
        nodes are put exactly in the plane.
    h_solid, h_edge, h_far
        Element sizes on the solids, near their edges, at the far field (mesh units).
    grow
        Distance from the solids over which the size grows from ``h_solid`` to ``h_far``
        (default 0.6 of the box's smallest extent).
    edge_grow
        Distance from the solids' curves at which the size has grown linearly from ``h_edge`` to
        ``h_solid`` (a graded band along leading and trailing edges, resolving a leading-edge radius);
        default None: from ``h_edge`` toward ``h_far`` over 20 ``h_solid`` (a thin band).
    fuse
        The solids intersect (a wing through a fuselage) and are fused first, sharing the junction.

    Returns
    -------
    points : (N, 3) float64
        Only the nodes the tetrahedra use, numbered compactly.
    tets : (T, 4) int64
        VTK order, positive volume.
    markers : dict
        Name -> triangles (F, 3) int64 with their normals out of the fluid: the solids in the order
        given, then ``symmetry`` and ``farfield``.
    """
    import gmsh  # noqa: PLC0415 (the [test] or [samples] extra)

    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    # interruptible=False: gmsh's own choice sets SIGINT to SIG_DFL and (gmsh 4.x forgets a `global`)
    # never restores it, so any later Ctrl-C or interrupt test would kill the interpreter outright.
    gmsh.initialize(["-nt", "1"], readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add(name)
        vols, boxes = _fluid(gmsh, solids, lo, hi, fuse)
        groups = _classify(gmsh, vols, boxes, list(solids), lo, hi, symmetry_axis, symmetry_at)
        faces = [t for n in solids for t in groups[n]]
        _size_fields(gmsh, faces, h_solid, h_edge, h_far, 0.6 * float(np.min(hi - lo)) if grow is None else grow,
                     edge_grow)
        gmsh.model.mesh.generate(3)
        node_tags, xyz = gmsh.model.mesh.getNodes()[:2]
        etypes, _, enodes = gmsh.model.mesh.getElements(3, vols[0][1])
        if list(etypes) != [4]:
            raise RuntimeError(f"{name}: gmsh made elements {list(etypes)}, expected linear tetrahedra")
        marker_tags = {g: _triangles(gmsh, tags, g) for g, tags in groups.items()}
    finally:
        gmsh.finalize()
    points, tets, markers = _compact(node_tags, xyz.reshape(-1, 3), enodes[0].reshape(-1, 4), marker_tags)
    points[unique_ids(markers["symmetry"]), symmetry_axis] = symmetry_at    # gmsh returns them to rounding
    return points, tets, orient_out_of_fluid(points, tets, markers)


def _fluid(gmsh, solids: dict[str, SolidBuilder], lo, hi, fuse: bool):
    """Build the solids, cut them (fused if asked) from the box: the fluid's volume and the solids'
    bounding boxes (2, 3) (measured only when there are several solids to tell apart)."""
    occ = gmsh.model.occ
    tags = {n: build(occ) for n, build in solids.items()}
    boxes = {}
    if len(tags) > 1:
        occ.synchronize()
        boxes = {n: np.array(gmsh.model.getBoundingBox(3, t)).reshape(2, 3) for n, t in tags.items()}
    tools = [(3, t) for t in tags.values()]
    if fuse:
        tools, _ = occ.fuse(tools[:1], tools[1:])
    box = occ.addBox(*lo, *(hi - lo))
    occ.cut([(3, box)], tools)
    occ.synchronize()
    vols = gmsh.model.getEntities(3)
    if len(vols) != 1:
        raise RuntimeError(f"the fluid is {len(vols)} volumes, expected one")
    return vols, boxes


def _classify(gmsh, vols, boxes, names: list[str], lo, hi, axis: int, at: float) -> dict[str, list[int]]:
    """The fluid's boundary surfaces by marker: symmetry plane, other box faces, else the solid whose
    bounding box holds the face (the smallest such box)."""
    groups = {n: [] for n in names}
    groups.update(symmetry=[], farfield=[])
    tol = 1e-6 * float(np.max(hi - lo))
    for dim, tag in gmsh.model.getBoundary(vols, oriented=False):
        bb = np.array(gmsh.model.getBoundingBox(dim, tag)).reshape(2, 3)
        flat = np.abs(bb[0] - bb[1]) < tol
        on_face = (np.abs(bb[0] - lo) < tol) | (np.abs(bb[0] - hi) < tol)
        on_box = [ax for ax in range(3) if flat[ax] and on_face[ax]]
        if on_box and on_box[0] == axis and abs(bb[0, axis] - at) < tol:
            groups["symmetry"].append(tag)
        elif on_box:
            groups["farfield"].append(tag)
        elif len(names) == 1:
            groups[names[0]].append(tag)
        else:
            holders = [n for n, b in boxes.items() if np.all(bb[0] >= b[0] - 1e-3) and np.all(bb[1] <= b[1] + 1e-3)]
            if not holders:
                raise RuntimeError(f"face {tag} {bb.tolist()} is in no solid's bounding box")
            groups[min(holders, key=lambda n: float(np.prod(np.ptp(boxes[n], axis=0))))].append(tag)
    for n, tags in groups.items():
        if not tags:
            raise RuntimeError(f"no surface classified as {n}")
    return groups


def _size_fields(gmsh, faces: list[int], h_solid: float, h_edge: float, h_far: float, grow: float,
                 edge_grow: float | None = None) -> None:
    """Background size: ``h_solid`` on ``faces`` growing to ``h_far`` over ``grow``, ``h_edge`` near
    their curves growing toward ``h_far`` over 20 ``h_solid`` (or reaching ``h_solid`` at ``edge_grow``);
    sizes from the boundary, points and curvature off."""
    curves = sorted({abs(c[1]) for s in faces for c in gmsh.model.getBoundary([(2, s)], oriented=False)})
    f = gmsh.model.mesh.field
    d_s = f.add("Distance")
    f.setNumbers(d_s, "SurfacesList", faces)
    f.setNumber(d_s, "Sampling", 60)
    t_s = f.add("Threshold")
    f.setNumber(t_s, "InField", d_s)
    f.setNumber(t_s, "SizeMin", h_solid)
    f.setNumber(t_s, "SizeMax", h_far)
    f.setNumber(t_s, "DistMin", 0.5 * h_solid)
    f.setNumber(t_s, "DistMax", grow)
    d_c = f.add("Distance")
    f.setNumbers(d_c, "CurvesList", curves)
    f.setNumber(d_c, "Sampling", 200 if edge_grow is None else 2000)
    t_c = f.add("Threshold")
    f.setNumber(t_c, "InField", d_c)
    f.setNumber(t_c, "SizeMin", h_edge)
    f.setNumber(t_c, "SizeMax", h_far)
    f.setNumber(t_c, "DistMin", 0.5 * h_edge)
    # edge_grow: the same ramp toward h_far, steep enough to reach h_solid at edge_grow
    f.setNumber(t_c, "DistMax", 20 * h_solid if edge_grow is None
                else 0.5 * h_edge + edge_grow * (h_far - h_edge) / max(h_solid - h_edge, 1e-12 * h_far))
    m = f.add("Min")
    f.setNumbers(m, "FieldsList", [t_s, t_c])
    f.setAsBackgroundMesh(m)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.Algorithm", 6)
    gmsh.option.setNumber("Mesh.Algorithm3D", 1)
    gmsh.option.setNumber("Mesh.Optimize", 1)


def _triangles(gmsh, surfaces: list[int], name: str) -> np.ndarray:
    """gmsh node tags (F, 3) of the triangles of ``surfaces``."""
    tris = []
    for s in surfaces:
        et, _, en = gmsh.model.mesh.getElements(2, s)
        if list(et) != [2]:
            raise RuntimeError(f"marker {name}: gmsh made surface elements {list(et)}, expected triangles")
        tris.append(en[0].reshape(-1, 3).astype(np.int64))
    return np.concatenate(tris)


def _compact(node_tags, xyz, tets_tags, marker_tags):
    """Points, tets (positive volume) and markers in a compact 0-based numbering of the nodes the
    tetrahedra use (gmsh tags are 1-based and may have gaps)."""
    tets_tags = tets_tags.astype(np.int64)
    used = unique_ids(tets_tags)
    lookup = np.full(int(max(node_tags.max(), used.max())) + 1, -1, dtype=np.int64)
    lookup[used] = np.arange(len(used))
    pos = np.full(len(lookup), -1, dtype=np.int64)
    pos[node_tags.astype(np.int64)] = np.arange(len(node_tags))
    points = xyz[pos[used]]
    tets = lookup[tets_tags]
    vol = tet_volumes(points, tets)
    tets[vol < 0] = tets[vol < 0][:, [0, 2, 1, 3]]              # VTK/SU2 orientation: all positive
    markers = {name: lookup[t] for name, t in marker_tags.items()}
    for name, t in markers.items():
        if np.any(t < 0):
            raise RuntimeError(f"marker {name} references a node that no tetrahedron uses")
    return points, tets, markers


def orient_out_of_fluid(points: np.ndarray, tets: np.ndarray, markers: dict[str, np.ndarray]
                        ) -> dict[str, np.ndarray]:
    """Each boundary triangle (F, 3) reordered where needed so that its normal points out of the
    fluid (away from the one tetrahedron it is a face of)."""
    n = len(points)
    faces = np.sort(np.concatenate([tets[:, [0, 1, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 3]],
                                    tets[:, [1, 2, 3]]]), axis=1)
    opposite = np.concatenate([tets[:, 3], tets[:, 2], tets[:, 1], tets[:, 0]])
    key = (faces[:, 0] * n + faces[:, 1]) * n + faces[:, 2]
    order = np.argsort(key)
    key_sorted = key[order]
    out = {}
    for name, tris in markers.items():
        s = np.sort(tris, axis=1)
        k = (s[:, 0] * n + s[:, 1]) * n + s[:, 2]
        i = np.searchsorted(key_sorted, k)
        if np.any(i >= len(key_sorted)) or np.any(key_sorted[np.minimum(i, len(key_sorted) - 1)] != k):
            raise RuntimeError(f"marker {name} has a triangle that is not a tetrahedron face")
        opp = points[opposite[order[i]]]
        p = points[tris]
        nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        inward = np.einsum("ij,ij->i", nrm, opp - p[:, 0]) > 0
        t = tris.copy()
        t[inward] = t[inward][:, [0, 2, 1]]
        out[name] = t
    return out


# ----------------------------------------------------------------------------------------------
# Half wings with the tip inside the domain (the tests and the robustness benchmark)
# ----------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class WingCase:
    """One generated wing mesh (see the module docstring).

    name
        Short name (used in file names and the benchmark table).
    planform
        The wing (axes, side, sweep, taper, kink, airfoils).
    tip
        ``flat`` (blunt cap) or ``round``.
    farfield
        Distance from the wing to the far-field box, in root chords.
    layers, first_layer, growth
        Boundary-layer prisms: number, first height (root chords), growth ratio. 0 layers: tets only.
    h_wing, h_edge, h_far
        Element sizes on the wing, at its edges and at the far field, in root chords.
    n_chord
        Points per airfoil side of the lofted sections.
    """

    name: str
    planform: Planform = field(default_factory=Planform)
    tip: str = "flat"
    farfield: float = 10.0
    layers: int = 0
    first_layer: float = 2e-4
    growth: float = 1.3
    h_wing: float = 0.06
    h_edge: float = 0.025
    h_far: float = 3.0
    n_chord: int = 41

    def __post_init__(self):
        if self.tip not in ("flat", "round"):
            raise ValueError(f"tip must be flat or round, got {self.tip!r}")
        if not self.farfield > 0:
            raise ValueError("farfield must be positive")

    def key(self) -> str:
        """Hash of every parameter and the generator version (the cache key)."""
        d = asdict(self)
        d["version"] = GENERATOR_VERSION
        return hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _cases() -> dict[str, WingCase]:
    rect = Planform(semi_span=3.0, root_chord=1.0, sections="xy")                      # span +z
    swept_left = Planform(semi_span=2.5, root_chord=1.0, taper=0.5, le_sweep_deg=30.0, dihedral_deg=5.0,
                          root_airfoil="2412", sections="xz", span_sign=-1.0)         # span -y
    transport = crm_planform(semi_span=3.0, root_chord=1.0, kink_te_extension=0.37, sections="yz")  # span x
    blunt = Planform(semi_span=2.0, root_chord=1.0, taper=0.6, le_sweep_deg=15.0, twist_tip_deg=-3.0,
                     closed_te=False, root_airfoil="0012", sections="zy", root_offset=(0.0, 0.0, 0.5))
    m6like = Planform(semi_span=1.5, root_chord=1.0, taper=0.56, le_sweep_deg=30.0, root_airfoil="0010",
                      sections="xz", span_sign=1.0)
    big = crm_planform(sections="xz", semi_span=29.38)                                  # metres
    cases = [
        WingCase("rect_z", rect),
        WingCase("rect_z_bl_ff5", rect, layers=6, farfield=5.0),
        WingCase("left_swept_round", swept_left, tip="round", layers=5),
        WingCase("transport_x_ff50", transport, farfield=50.0, h_far=10.0),
        WingCase("transport_x_bl", transport, layers=6, first_layer=1e-4),
        WingCase("blunt_te_x", blunt, tip="round"),
        WingCase("m6like_ff50_bl", m6like, farfield=50.0, h_far=10.0, layers=4),
        WingCase("crm_metres", big, h_wing=0.06, h_edge=0.025),
        # generated after the defaults were chosen (held out from that choice; they passed on first run)
        WingCase("right_dihedral_zx_bl", Planform(semi_span=2.0, root_chord=1.0, taper=0.35, le_sweep_deg=35.0,
                                                  dihedral_deg=7.0, root_airfoil="2410", tip_airfoil="0008",
                                                  sections="zx"),
                 tip="round", layers=8, first_layer=5e-5, growth=1.25, farfield=20.0, h_far=5.0),
        WingCase("thick_left_x_ff50_bl", Planform(semi_span=2.5, root_chord=1.0, taper=0.8, root_airfoil="4418",
                                                  sections="yz", span_sign=-1.0, twist_tip_deg=-4.0),
                 layers=6, farfield=50.0, h_far=10.0),
        WingCase("kinked_z_blunt_bl_ff5", crm_planform(semi_span=3.0, root_chord=1.0, kink_te_extension=0.37,
                                                       sections="xy", closed_te=False),
                 layers=5, farfield=5.0),
        # generated after the flap's blend ramp was chosen (2026-12-04; held out from that choice)
        WingCase("left_swept_z_bl", Planform(semi_span=2.2, root_chord=1.0, taper=0.4, le_sweep_deg=28.0,
                                             dihedral_deg=3.0, root_airfoil="2415", tip_airfoil="0010",
                                             sections="xy", span_sign=-1.0),
                 layers=5, first_layer=1e-4, farfield=15.0, h_far=4.0),
        WingCase("thin_left_y_round_bl", Planform(semi_span=2.5, root_chord=1.0, taper=0.9, root_airfoil="0009",
                                                  sections="xz", span_sign=-1.0, twist_tip_deg=2.0),
                 tip="round", layers=6, first_layer=5e-5),
        WingCase("transport_zx_blunt_bl", crm_planform(semi_span=3.0, root_chord=1.0, kink_te_extension=0.3,
                                                       sections="zx", closed_te=False),
                 layers=4, farfield=8.0),
        # a RANS wing: 32 prism layers from a first cell of 1e-6 chord (the wall layer's own benchmark)
        WingCase("rect_z_rans32", rect, layers=32, first_layer=1e-6, growth=1.25),
    ]
    return {c.name: c for c in cases}


#: Named cases with variety: span along x, y and z; left and right; kinked transport; flat and
#: round tips; sharp and blunt trailing edges; prism layers (4 to 8, first layer 5e-5 to 2e-4
#: chords); far field at 5, 10, 20 and 50 chords; thin (NACA 0008) to thick (4418) sections.
CASES: dict[str, WingCase] = _cases()


def _sections(case: WingCase) -> list[np.ndarray]:
    """Mesh coordinates of the lofted sections root -> tip (each (n, 3), closed or open TE)."""
    pf = case.planform
    etas = [0.0, 1.0] if pf.kink_eta is None else [0.0, pf.kink_eta, 1.0]
    out = planform_sections(pf, etas, case.n_chord)
    coords = pf.airfoil_coords(np.array(etas), 2 * case.n_chord - 1)
    if case.tip == "round":
        tip_coords = coords[-1]
        tip_chord = float(pf.chord(1.0))
        r = 0.5 * float(np.ptp(tip_coords[:, 1])) * tip_chord       # half the tip thickness
        camber = 0.5 * (tip_coords + tip_coords[::-1])[:, 1]           # mid-line (same x both sides)
        for phi in np.radians([25.0, 50.0, 70.0]):
            c = tip_coords.copy()
            c[:, 1] = camber + (tip_coords[:, 1] - camber) * np.cos(phi)
            local = pf.local_points(np.array([1.0]), c)[0]
            local[:, 2] += r * np.sin(phi)
            out.append(pf.to_mesh(local))
    return out


def _domain(case: WingCase, sections: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The far-field box: ``farfield`` root chords round the wing, cut at the root plane."""
    pts = np.concatenate(sections)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    d = case.farfield * case.planform.root_chord
    lo, hi = lo - d, hi + d
    s = case.planform.axes[2]
    root = case.planform.root_offset[s]
    if case.planform.span_sign > 0:
        lo[s] = root
    else:
        hi[s] = root
    return lo, hi


def wing_volume_mesh(case: WingCase) -> Mesh:
    """The mesh of ``case`` (see the module docstring). Raises RuntimeError if a cell is not valid."""
    sections = _sections(case)
    lo, hi = _domain(case, sections)
    pf = case.planform
    c, s = pf.root_chord, pf.axes[2]
    points, tets, markers = fluid_tets({"wing": partial(loft, sections=sections)}, lo, hi, symmetry_axis=s,
                                       symmetry_at=pf.root_offset[s], h_solid=case.h_wing * c,
                                       h_edge=case.h_edge * c, h_far=case.h_far * c, grow=4 * case.h_far * c,
                                       name=case.name)
    if case.layers:
        mesh = add_prism_layers(points, tets, markers, span_axis=s, root=pf.root_offset[s], layers=case.layers,
                                first=case.first_layer * c, growth=case.growth)
    else:
        mesh = Mesh(points=points, dim=3, cells=[CellBlock("tetra", tets)],
                    markers={k: [CellBlock("triangle", v)] for k, v in markers.items()})
    q = cell_quality(mesh.points, mesh.cells)
    if q.min() <= 0:
        raise RuntimeError(f"{case.name}: {int(np.sum(q <= 0))} generated cells have quality <= 0")
    return mesh


def write_case(case: WingCase | str, folder: str | Path) -> Path:
    """Write the case's mesh as ``<folder>/<name>-<key>.su2`` unless it is already there; its path."""
    case = CASES[case] if isinstance(case, str) else case
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{case.name}-{case.key()}.su2"
    if not path.exists():
        write_mesh(wing_volume_mesh(case), path)
    return path


def smaller(case: WingCase, factor: float = 1.6) -> WingCase:
    """The same wing with every element size multiplied by ``factor`` (a quicker mesh for tests)."""
    return replace(case, name=f"{case.name}_s", h_wing=case.h_wing * factor, h_edge=case.h_edge * factor,
                   n_chord=max(21, int(case.n_chord / factor)))
