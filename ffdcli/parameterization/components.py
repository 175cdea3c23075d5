"""Several components in one mesh: a wing, a tail, a fin, and a wing whose root meets a body.

A design is a list of components (SPEC, ``components:``); the single-component form of the design
file is one component with an empty name. Each component is a small value: its surface markers, its
prepared box (axes and root detected on its own surface), its changes. The run
(:class:`ffdcli.app.pipeline.DesignRun`) concatenates the components' surfaces for the one volume motion,
and their lattices for the derivatives: the basis matrix of the run is block diagonal (each surface
point belongs to one component), so ``dX/dv = B @ dP'/dv`` holds for the whole design unchanged.

Rules where SPEC is silent (docs/design-choices.md, docs/design-file.md):

- **Axes of a component.** The chord axis of every lifting surface is the flow direction, so when a
  component after the first has no ``box.sections``, its chord axis is the first component's and its
  thickness axis the smaller extent of the other two (a fin: span along the wing's thickness axis).
- **Names.** Variables ``<component>.c<index>...``, constraints ``<component>.k<index>...``; the
  single-component form keeps ``c<index>...``.
- **Root on a body.** A marker that shares nodes with a component's surface and is neither another
  component nor a plane normal to the component's span (a symmetry plane) is a *body* the root
  meets. The sections whose B-spline basis reaches a node shared with the body are frozen (their
  control points stay where they were, bit for bit): the shared nodes do not move and the motion of
  the rest of the wing is a B-spline that vanishes up to the junction with all its derivatives of
  order < degree (C^2 for cubic), the B-spline counterpart of SU2's ``FFD_CONTINUITY``. A ``{root,
  tip}`` law of twist or chord is then linear from the last frozen section to the tip; a list that
  moves a frozen section, a twist ``root`` other than 0 or a chord ``root`` other than 1 is refused.
- **Overlapping boxes.** Two components whose lattices overlap (a surface point of one lies inside
  the other's lattice) are an error naming both: the other surface would not follow that lattice.
- **Shared nodes.** Two components may not share a marker, nor surface nodes.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ffdcli.errors import InputError
from ffdcli.lattice.embedding import embed
from ffdcli.lattice.spline import basis_derivs
from ffdcli.mesh.idsets import unique_ids
from ffdcli.parallel.distributed import global_ids
from ffdcli.parameterization.bounds import Bounds, make_bounds
from ffdcli.parameterization.changes import Chord, Shape, Twist, apply_changes
from ffdcli.parameterization.changes import design_variables as change_variables
from ffdcli.parameterization.changes import set_design_variables as set_change_values
from ffdcli.parameterization.derivatives import lattice_jacobian

AXIS_NAMES = "xyz"


@dataclass(frozen=True)
class ComponentSpec:
    """One component as the design file gives it.

    name
        ``""`` for the single-component form (variables ``c0...``), else the component's name.
    surface
        Marker names, or None for the default surface rule (single-component form only).
    box
        :class:`ffdcli.settings.BoxSettings`.
    changes_spec
        The ``changes`` list as written.
    key
        Key path of the component in the design file (``"components[1]"``), ``""`` for the single form.
    """

    name: str
    surface: tuple[str, ...] | None
    box: object
    changes_spec: tuple
    key: str = ""

    @property
    def prefix(self) -> str:
        """Prefix of the component's variable and constraint names (``"htail."`` or ``""``)."""
        return f"{self.name}." if self.name else ""

    def subkey(self, key: str) -> str:
        """A key of this component's part of the design file: ``changes[0].twist`` ->
        ``components[1].changes[0].twist``."""
        return f"{self.key}.{key}" if self.key else key


@dataclass(frozen=True)
class Junction:
    """The root of a component meets a body marker: the sections ``0 .. frozen - 1`` stay fixed."""

    marker: str
    nodes: np.ndarray          # mesh ids of the surface nodes shared with the body
    frozen: int
    at_tip: bool = False       # the body meets the lattice's far end (span parameter past the middle): root reversed

    def summary(self) -> dict:
        return {"marker": self.marker, "nodes": int(len(self.nodes)), "frozen_sections": int(self.frozen)}


@dataclass(frozen=True, eq=False)
class Component:
    """A component prepared for a run: its spec, box and embedding, changes and junction."""

    spec: ComponentSpec
    prep: object               # ffdcli.app.pipeline.PreparedBox
    changes: tuple
    junction: Junction | None = None

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def box(self):
        return self.prep.box

    @property
    def P0(self) -> np.ndarray:
        return self.prep.box.control_points

    @property
    def frozen(self) -> int:
        return 0 if self.junction is None else self.junction.frozen

    def with_changes(self, changes) -> Component:
        return replace(self, changes=tuple(changes))

    # -- lattice -------------------------------------------------------------------------------
    def freeze(self, P: np.ndarray) -> np.ndarray:
        """``P`` with the frozen sections put back where they were (bit for bit)."""
        f = self.frozen
        if not f:
            return P
        P = np.array(P, dtype=float, copy=True)
        P[:, :f] = self.P0[:, :f]
        return P

    def lattice_jacobian(self) -> np.ndarray:
        """dP'/dv (n_ctrl*3, n_vars) of this component's variables (zero rows for frozen sections)."""
        J = lattice_jacobian(self.P0, self.box.frame, list(self.changes))
        f = self.frozen
        if f:
            n, m, l, _ = self.P0.shape
            Jr = J.reshape(n, m, l, 3, J.shape[1])
            Jr[:, :f] = 0.0
        return J

    def summary(self) -> dict:
        out = {"name": self.name or None, "surface": list(self.prep.surface.names), **self.box.summary()}
        out["root_on"] = None if self.junction is None else self.junction.marker
        if self.junction is not None:
            out["junction"] = self.junction.summary()
        return out


# ----------------------------------------------------------------------------------------------
# Specs from the design file
# ----------------------------------------------------------------------------------------------

def specs_of(design) -> list[ComponentSpec]:
    """The components of a loaded design (the single-component form is one with an empty name)."""
    comps = getattr(design, "components", None)
    if comps:
        return list(comps)
    surface = None if design.surface is None else tuple(design.surface)
    return [ComponentSpec(name="", surface=surface, box=design.box, changes_spec=tuple(design.changes_spec))]


def check_markers(specs: list[ComponentSpec], mesh, *, path=None) -> None:
    """Every component has a surface; no marker belongs to two components. Raises InputError."""
    owner: dict[str, str] = {}
    for spec in specs:
        if spec.name and not spec.surface:
            raise InputError(f"component {spec.name!r} has no surface: give surface: <marker> (markers: "
                             f"{', '.join(mesh.markers)})", path=path, key=spec.subkey("surface"))
        for name in spec.surface or ():
            if name in owner:
                raise InputError(f"marker {name!r} is the surface of two components, {owner[name]!r} and "
                                 f"{spec.name!r}; each marker belongs to one component", path=path,
                                 key=spec.subkey("surface"))
            owner[name] = spec.name


def sections_for(points: np.ndarray, chord_axis: int) -> str:
    """``box.sections`` of a component whose chord axis is given (that of the first component):
    the thickness axis is the smaller extent of the two others."""
    ext = np.ptp(np.asarray(points, dtype=float), axis=0)
    rest = [a for a in range(3) if a != chord_axis]
    thick = min(rest, key=lambda a: ext[a])
    return AXIS_NAMES[chord_axis] + AXIS_NAMES[thick]


# ----------------------------------------------------------------------------------------------
# Root on a body
# ----------------------------------------------------------------------------------------------

def marker_ids(mesh, name: str) -> np.ndarray:
    blocks = mesh.markers[name]
    if not blocks:
        return np.zeros(0, dtype=np.int64)
    return unique_ids(*[b.data for b in blocks])


def _flat_normal_to(mesh, name: str, axis: int, size: float) -> bool:
    """Every face of marker ``name`` lies in a plane normal to mesh axis ``axis``: a symmetry plane
    of the span, or several (the two side planes of an extruded airfoil under one name)."""
    tol = 1e-6 * max(size, 1e-300)
    for blk in mesh.markers[name]:
        if len(blk.data) and blk.type != "vertex":
            c = mesh.points[blk.data, axis]
            if float(np.max(c.max(axis=1) - c.min(axis=1))) > tol:
                return False
    return True


def root_contact(mesh, surface_ids: np.ndarray, span_axis: int, skip=()) -> tuple[str, np.ndarray] | None:
    """(marker, shared node ids) of the body a surface meets, or None.

    A body is a marker not in ``skip`` (the surface's own and the other components' markers) that
    shares nodes with the surface and whose faces do not all lie in planes normal to the span axis
    (a symmetry plane, or the side planes of an extruded airfoil).
    With several, the one sharing the most nodes."""
    pts = mesh.points[surface_ids]
    size = float(np.linalg.norm(np.ptp(pts, axis=0))) if len(pts) else 0.0
    best = None
    for name in mesh.markers:
        if name in skip:
            continue
        ids = marker_ids(mesh, name)
        shared = np.intersect1d(ids, surface_ids, assume_unique=True)
        if not len(shared) or _flat_normal_to(mesh, name, span_axis, size):
            continue
        if best is None or len(shared) > len(best[1]):
            best = (name, shared)
    return best


def find_junction(mesh, prep, own_markers, other_component_markers=()) -> Junction | None:
    """The body marker the component's root meets (:func:`root_contact`), with the sections to
    freeze: every section whose B-spline basis is not zero at a shared node. None for a root on a
    symmetry plane, a free root, or a 2D mesh."""
    box = prep.box
    if box.dim != 3:
        return None
    surf_ids = prep.surface.ids
    found = root_contact(mesh, surf_ids, box.axes.span, set(own_markers) | set(other_component_markers))
    if found is None:
        return None
    name, shared = found
    rows = np.searchsorted(surf_ids, shared)
    emb = prep.embedding
    v = emb.params[rows[emb.inside[rows]], 1]
    if not len(v):
        return Junction(name, shared, 0)
    knots = box.knots[1]
    at_tip = bool(np.median(v) > 0.5 * (knots[0] + knots[-1]))
    return Junction(name, shared, frozen_sections(knots, box.degree[1], v, box.shape[1]), at_tip)


def frozen_sections(knots, degree: int, v: np.ndarray, m: int) -> int:
    """How many root sections to freeze so that the motion and its first span derivative vanish at
    the span parameters ``v`` of the junction nodes (C1): one past the last section whose basis
    function or its derivative is non-zero at some ``v``."""
    first, ders = basis_derivs(knots, degree, np.asarray(v, dtype=float), nder=1)
    live = (np.abs(ders[0]) > 0) | (np.abs(ders[1]) > 0)          # (N, p + 1)
    last = first[:, None] + np.arange(degree + 1)[None, :]
    return int(min(np.max(np.where(live, last, -1)) + 1, m))


def check_body_changes(spec: ComponentSpec, changes, junction: Junction, error) -> list:
    """Refuse changes that move a frozen section; re-base ``{root, tip}`` laws on the first free
    section. ``error(message, key) -> Exception``. Returns the changes to use."""
    f = junction.frozen
    out = []
    for index, (change, item) in enumerate(zip(changes, spec.changes_spec, strict=True)):
        (kind, raw), = item.items()
        key = f"changes[{index}].{kind}"
        where = (f"its root meets {junction.marker!r}, so sections 0..{f - 1} (those carrying the junction) "
                 f"stay fixed")
        if isinstance(change, (Twist, Chord)):
            rest = 0.0 if isinstance(change, Twist) else 1.0
            if isinstance(raw, list):
                bad = [j for j in range(min(f, len(raw))) if raw[j] != rest]
                if bad:
                    raise error(f"moves section {bad[0]} of a wing on a body: {where}; give {rest:g} for "
                                f"the first {f} values", key)
            elif isinstance(raw, dict):
                if raw.get("root", rest) != rest:
                    raise error(f"moves the root section of a wing on a body ({kind} root {raw['root']}): "
                                f"{where}; remove root (it is {rest:g})", key + ".root")
                change = replace(change, law=rebase_law(change.law, f - 1))
        elif isinstance(change, Shape) and change.sections is not None:
            bad = [j for j in change.sections if j < f]
            if bad:
                raise error(f"moves section {bad[0]} of a wing on a body: {where}", key + ".sections")
        out.append(change)
    return out


def check_frozen_motion(comp: Component, error) -> None:
    """The rule that a change which moves the lattice moves the wing: a change whose motion lies only on
    the frozen sections of a wing on a body (all of them when the junction reaches every section, or
    when the root is at the wrong end) would be a design that silently moves nothing.
    ``error(message, key) -> Exception``; the key is the change's, or ``box.root`` for a reversed root."""
    j = comp.junction
    if j is None or not j.frozen:
        return
    m = comp.P0.shape[1]
    for index, (change, item) in enumerate(zip(comp.changes, comp.spec.changes_spec, strict=True)):
        P = apply_changes(comp.P0, comp.box.frame, [change])
        if np.array_equal(P, comp.P0) or not np.array_equal(comp.freeze(P), comp.P0):
            continue
        kind = next(iter(item))
        what = (f"moves only sections of the lattice that stay fixed: the root meets {j.marker!r}, and the "
                f"junction holds sections 0..{j.frozen - 1} of {m}")
        if j.at_tip:
            raise error(f"changes[{index}].{kind} {what}; the body is at the far end of the box's span, so the "
                        f"root is on the wrong side: {root_advice(comp)}", "box.root")
        raise error(f"{what}, so nothing is free to move; give the lattice more spanwise sections (box.points[1] "
                    f"> {m}) or move sections beyond the junction", f"changes[{index}].{kind}")


def root_advice(comp: Component) -> str:
    """What to do when the root is at the end away from the body: give ``box.root`` the other end, or,
    when the file gave it, that or leave it out (the detection then looks for the root plane)."""
    given = getattr(getattr(comp.spec, "box", None), "root", None)
    now = given or comp.box.axes.root
    other = "max" if now == "min" else "min"
    if given is not None:
        return f"the file gives box.root: {given}; give box.root: {other}, or leave it out (detected)"
    return f"the root was detected at the {now} end; give box.root: {other}"


def rebase_law(law, first: int):
    """A ``{root, tip}`` :class:`~ffdcli.parameterization.changes.SectionLaw` made linear from section ``first`` (the
    root value there and inboard of it) to the tip."""
    m = len(law.base)
    if first <= 0 or first >= m - 1:
        return law
    s = np.clip((np.arange(m) - first) / (m - 1 - first), 0.0, None)
    if law.suffixes == (".tip",):
        root = law.base[0]          # default_root * (1 - s) at j = 0
        return replace(law, base=root * (1.0 - s), basis=s[:, None].copy())
    return replace(law, basis=np.stack([1.0 - s, s], axis=1))


# ----------------------------------------------------------------------------------------------
# Several components together
# ----------------------------------------------------------------------------------------------

def check_shared_nodes(components: list[Component], *, path=None) -> None:
    """No surface node belongs to two components."""
    for a in range(len(components)):
        for b in range(a + 1, len(components)):
            ca, cb = components[a], components[b]
            both = np.intersect1d(ca.prep.surface.ids, cb.prep.surface.ids, assume_unique=True)
            if len(both):
                node = int(global_ids(ca.prep.mesh, both[:1])[0])
                raise InputError(f"components {ca.name!r} and {cb.name!r} share {len(both)} surface nodes "
                                 f"(e.g. node {node}); components must be separate markers that do "
                                 "not touch", path=path)


def check_overlap(components: list[Component], *, path=None) -> None:
    """Two lattices overlap when a surface point of one lies inside the other's lattice: error."""
    for a, ca in enumerate(components):
        Pa = ca.P0.reshape(-1, 3)
        lo, hi = Pa.min(axis=0), Pa.max(axis=0)
        for b, cb in enumerate(components):
            if a == b:
                continue
            X = cb.prep.surface.points
            near = np.all((X >= lo) & (X <= hi), axis=1)
            if not near.any():
                continue
            emb = embed(ca.box.lattice(), ca.box.core_points(X[near]))
            if emb.inside.any():
                k = int(np.flatnonzero(near)[np.flatnonzero(emb.inside)[0]])
                node = int(global_ids(cb.prep.mesh, cb.prep.surface.ids[k:k + 1])[0])
                raise InputError(f"the boxes of components {ca.name!r} and {cb.name!r} overlap: surface point "
                                 f"{node} of {cb.name!r} lies inside the lattice of "
                                 f"{ca.name!r} (move them apart, or make {ca.name!r}'s box smaller with "
                                 "box.margin)", path=path)


@dataclass(frozen=True, eq=False)
class Layout:
    """Where each component's surface points sit in the run's surface (the union of all, sorted)."""

    surface_ids: np.ndarray                      # (S,) sorted mesh ids of every component's surface
    rows: tuple[np.ndarray, ...]                 # per component: its points' rows in surface_ids
    ctrl_offsets: tuple[int, ...] = field(default=())    # first control point of each component
    var_offsets: tuple[int, ...] = field(default=())     # first variable of each component


def layout(components: list[Component]) -> Layout:
    ids = np.concatenate([c.prep.surface.ids for c in components])
    union = unique_ids(ids)
    rows = tuple(np.searchsorted(union, c.prep.surface.ids) for c in components)
    ctrl = np.cumsum([0] + [int(np.prod(c.P0.shape[:3])) for c in components])
    nv = np.cumsum([0] + [sum(ch.size for ch in c.changes) for c in components])
    return Layout(union, rows, tuple(int(x) for x in ctrl), tuple(int(x) for x in nv))


def design_variables(components: list[Component]) -> tuple[list[str], np.ndarray]:
    """Names (``<component>.c<index>...``; single form ``c<index>...``) and values of every variable."""
    names, values = [], []
    for comp in components:
        n, v = change_variables(list(comp.changes))
        names += [comp.spec.prefix + x for x in n]
        values.append(v)
    return names, (np.concatenate(values) if values else np.zeros(0))


def variable_bounds(components: list[Component], design) -> Bounds:
    """The :class:`~ffdcli.parameterization.bounds.Bounds` of every variable: natural ones from the changes,
    the design file's ``bounds:`` checked against the names and values (an unknown name, lower above
    upper, a value outside its bounds: :class:`InputError` naming ``bounds.<key>`` and its line). The one
    validation of ``bounds:``: ``load_run`` calls it for every command, ``DesignModel`` keeps its result."""
    names, values = design_variables(components)
    natural = [np.zeros((0, 2))]
    for comp in components:          # design_bounds, each change's refusal named by its key and line
        P = np.array(comp.P0, dtype=float, copy=True)
        for index, (change, item) in enumerate(zip(comp.changes, comp.spec.changes_spec, strict=True)):
            try:
                natural.append(change.bounds(P, comp.box.frame))
                P = change.apply(P, comp.box.frame)
            except InputError as e:
                if e.path is not None or not hasattr(design, "error"):
                    raise
                raise design.error(e.message, comp.spec.subkey(f"changes[{index}].{next(iter(item))}")) from None
    natural = np.concatenate(natural, axis=0)
    spec = (getattr(design, "data", None) or {}).get("bounds")
    return make_bounds(names, natural, spec, values=values, error=getattr(design, "error", None))


def set_design_variables(components: list[Component], values) -> list[Component]:
    vals = np.asarray(values, dtype=float).reshape(-1)
    sizes = [sum(ch.size for ch in c.changes) for c in components]
    if vals.size != sum(sizes):
        raise ValueError(f"expected {sum(sizes)} design-variable values, got {vals.size}")
    out, at = [], 0
    for comp, size in zip(components, sizes, strict=True):
        out.append(comp.with_changes(set_change_values(list(comp.changes), vals[at:at + size])))
        at += size
    return out
