"""The settings values a run is made of: what the user chose about the lattice (and the volume).

This module is light on purpose (the standard library and :mod:`ffdcli.errors` only): the design
file, the command line and the cache import it without paying for numpy, numba or scipy, so that
every other module can import it at the top and ``ffd schema`` / ``ffd --help`` stay fast.

Each settings value is a frozen dataclass that knows

``checked(...)``
    itself after checking against what it is used on (an :class:`~ffdcli.errors.InputError` naming
    the key otherwise), with every default filled in;
``as_dict()`` / ``get_cache_key()``
    its JSON form and a short stable digest of it (as black's ``Mode.get_cache_key``): the cache of
    a box is keyed by the settings that made it.

The rules of the lattice size live here and nowhere else: the default points
(:data:`DEFAULT_POINTS`), the most points per direction (:data:`MAX_POINTS`), the supported spline
degrees (1 to :data:`MAX_DEGREE`) and the default degree (:func:`default_degree`).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field, fields, replace

from ffdcli.errors import InputError

#: Control points when the user gives none: the paper's wing lattice, and its airfoil lattice.
DEFAULT_POINTS = {3: (6, 8, 2), 2: (6, 5)}
#: The most control points in one direction of a lattice (an FFD lattice has tens; millions would
#: run out of memory or time).
MAX_POINTS = 256
#: The highest B-spline degree the lattice kernels support (their work arrays are sized by it).
MAX_DEGREE = 5
#: Planes of the airfoil sections (``box.sections``): chord axis, then thickness axis.
SECTION_CHOICES = ("xy", "xz", "yz", "yx", "zx", "zy")
#: Ends of the span axis where the root may be (``box.root``).
ROOT_CHOICES = ("min", "max")
#: The default margin between the surface and the lattice, as a fraction of the local chord.
DEFAULT_MARGIN = 0.02


def default_degree(points: int) -> int:
    """The degree of a direction with ``points`` control points when none is given: min(3, p - 1)."""
    return min(3, int(points) - 1)


def degree_problem(points, degree) -> tuple[int, str] | None:
    """The one rule of degree against points, as ``(direction, message)`` of the first direction
    that breaks it, or None: 1 <= degree <= :data:`MAX_DEGREE` and degree < points.

    ``points`` and ``degree`` are sequences with one entry per direction.
    """
    for d, (p, q) in enumerate(zip(points, degree)):
        p, q = int(p), int(q)
        if not 1 <= q <= MAX_DEGREE:
            return d, f"degree {q} in direction {d} is not supported: use 1 to {MAX_DEGREE}"
        if q >= p:
            return d, (f"degree {q} in direction {d} needs more than {q} control points (at least "
                       f"{q + 1} points), the lattice has {p}")
    return None


def check_degree(points, degree, *, path=None, key: str | None = "box.degree") -> None:
    """:func:`degree_problem` as an :class:`InputError` naming ``key[d]`` (no key if ``None``)."""
    problem = degree_problem(points, degree)
    if problem is not None:
        d, message = problem
        raise InputError(message, path=path, key=None if key is None else f"{key}[{d}]",
                         hint="lower the degree or add points")


@dataclass(frozen=True)
class BoxSettings:
    """What the user chooses about the lattice (``box:`` in the design file, options of ``ffd box``).

    points
        (n, m, l) in 3D, (n, l) in 2D: chordwise, spanwise, thickness control points.
        ``None`` = the default of the mesh's dimension, :data:`DEFAULT_POINTS`.
    degree
        Per direction; ``None`` means :func:`default_degree` of each direction's points.
    sections
        ``"xy"`` etc. (chord axis, thickness axis); ``None`` = detected.
    margin
        Clearance between the surface and the lattice, as a fraction of the local chord.
    root
        ``"min"``/``"max"``: the end of the span axis where the root is; ``None`` = detected.
    file
        A Plot3D lattice to use instead of building one (pyGeo/DAFoam users' boxes).
    block
        Which block of a multi-block Plot3D ``file`` (0-based; one component per block, e.g. the
        wing and the tail of the DPW4 lattice); ``None`` for a single-block file.
    refine
        Regions with more control points, by exact knot insertion (:mod:`ffdcli.box.refine`): a
        tuple of ``("span", a, b, N)`` (N more sections between span fractions a and b) and
        ``("chord", a, b, N)`` (N more chordwise points between chord fractions a and b).
    """

    points: tuple[int, ...] | None = None
    degree: tuple[int, ...] | None = None
    sections: str | None = None
    margin: float = DEFAULT_MARGIN
    root: str | None = None
    file: str | None = None
    block: int | None = None
    refine: tuple[tuple, ...] = ()

    def degrees(self, dim: int | None = None) -> tuple[int, ...]:
        """The degree per direction: as given, else :func:`default_degree` of the points (those of
        ``dim``'s default when no points are set)."""
        if self.degree is not None:
            return tuple(int(d) for d in self.degree)
        points = self.points if self.points is not None or dim is None else DEFAULT_POINTS[dim]
        if points is None:
            raise ValueError("BoxSettings.degrees() needs points or the mesh dimension")
        return tuple(default_degree(p) for p in points)

    def checked(self, dim: int, *, path=None, key: str = "box") -> BoxSettings:
        """These settings after checking them against the mesh dimension; InputError if wrong.

        The result has ``points`` and ``degree`` filled in."""
        want = 3 if dim == 3 else 2
        pts = tuple(int(p) for p in (self.points or DEFAULT_POINTS[want]))
        if len(pts) != want:
            shape = "[n, m, l] (chordwise, spanwise, thickness)" if want == 3 else \
                "[n, l] (chordwise, thickness) for a 2D mesh"
            raise InputError(f"expected {want} numbers {shape}, got {list(pts)}", path=path,
                             key=f"{key}.points")
        if min(pts) < 2:
            raise InputError(f"every direction needs at least 2 control points, got {list(pts)}",
                             path=path, key=f"{key}.points")
        if max(pts) > MAX_POINTS:
            raise InputError(f"at most {MAX_POINTS} control points per direction, got {list(pts)}",
                             path=path, key=f"{key}.points")
        deg = replace(self, points=pts).degrees()
        if len(deg) != want:
            raise InputError(f"expected {want} degrees, got {list(deg)}", path=path, key=f"{key}.degree")
        check_degree(pts, deg, path=path, key=f"{key}.degree")
        if not math.isfinite(self.margin) or not 0 <= self.margin <= 1:
            raise InputError(f"margin is a fraction of the local chord in [0, 1], got {self.margin}",
                             path=path, key=f"{key}.margin")
        for q, (what, a, b, count) in enumerate(self.refine):
            if what not in ("span", "chord") or not 0.0 <= a < b <= 1.0 or not 1 <= count <= 32:
                raise InputError(f"a refine region is {{span: [a, b], sections: N}} or {{chord: [a, b], points: N}} "
                                 f"with 0 <= a < b <= 1 and 1 <= N <= 32, got {what} [{a:g}, {b:g}] {count}",
                                 path=path, key=f"{key}.refine[{q}]")
            if what == "span" and dim != 3:
                raise InputError("a 2D box has no span to refine; use {chord: [a, b], points: N}",
                                 path=path, key=f"{key}.refine[{q}]")
        return replace(self, points=pts, degree=deg)

    def with_options(self, **options) -> BoxSettings:
        """These settings with every option that is given (not None) in place of theirs: how the
        options of ``ffd box`` (or a script's) go over a design file's ``box:``.

        New ``points`` without a ``degree`` drop the old degree (it was chosen for the old points):
        the default of the new points applies."""
        given = {k: v for k, v in options.items() if v is not None}
        out = replace(self, **given)
        if "points" in given and "degree" not in given:
            out = replace(out, degree=None)
        return out

    def as_dict(self) -> dict:
        """The settings as JSON values (tuples as lists)."""
        d = asdict(self)
        d["points"] = None if self.points is None else [int(p) for p in self.points]
        d["degree"] = None if self.degree is None else [int(q) for q in self.degree]
        d["margin"] = float(self.margin)
        del d["refine"]
        if self.refine:            # only when given: the cache keys of unrefined boxes stay as they were
            d["refine"] = [[str(r[0]), float(r[1]), float(r[2]), int(r[3])] for r in self.refine]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> BoxSettings:
        """The inverse of :meth:`as_dict`."""
        return cls(points=None if d.get("points") is None else tuple(d["points"]),
                   degree=None if d.get("degree") is None else tuple(d["degree"]),
                   sections=d.get("sections"), margin=float(d.get("margin", DEFAULT_MARGIN)),
                   root=d.get("root"), file=d.get("file"), block=d.get("block"),
                   refine=tuple(tuple(r) for r in d.get("refine", ())))

    def get_cache_key(self) -> str:
        """A short digest of these settings: equal settings, equal key (part of the box cache key)."""
        blob = json.dumps(self.as_dict(), sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]


# --------------------------------------------------------------------------------------------------
# WarpSettings (how the volume mesh follows the surface) comes here from ffdcli/warp.py (the `vol`
# engineer moves it): a frozen dataclass with checked()/as_dict()/get_cache_key() like BoxSettings.
# --------------------------------------------------------------------------------------------------


# ----------------------------------------------------------------------------------------------
# The volume mesh: how it follows the surface (ffdcli.volume.warp) and the quality gate (ffdcli.quality.gate)

#: Volume-motion methods.
METHODS = ("idw", "none")
#: What each surface node's neighbourhood carries along (``volume.carry``).
CARRY = ("gradient", "rotation")
#: How the near-wall layer of a mesh with thin first cells moves (ffdcli.volume.layer_motion).
WALL_LAYER = ("rigid", "none")


def _doc(text: str) -> dict:
    return {"doc": text}


@dataclass(frozen=True)
class WarpSettings:
    """How the volume mesh follows the surface (``volume:`` in the design file).

    Every field carries a one-line description in ``metadata["doc"]`` (the design-file schema
    uses them).
    """

    method: str = field(default="idw", metadata=_doc(
        "idw: every node follows the surface by inverse-distance weighting (default); "
        "none: only the surface nodes move"))
    a: float = field(default=3.0, metadata=_doc(
        "exponent of the long-range weight term (L/d)^a"))
    b: float = field(default=5.0, metadata=_doc(
        "exponent of the short-range weight term (alpha L/d)^b; must be at least a"))
    alpha: float = field(default=1.0, metadata=_doc(
        "scale of the short-range term: it dominates closer than alpha^(b/(b-a)) L"))
    ldef: float | None = field(default=None, metadata=_doc(
        "reference length L in mesh units; default: diagonal of the surface's bounding box"))
    carry: str = field(default="gradient", metadata=_doc(
        "what the volume near each surface node carries along besides its translation: gradient "
        "(default): the FFD map's local deformation gradient F, so the cells at the wall deform "
        "exactly as the FFD deforms space there, also where faces meet at a sharp trailing edge "
        "or tip; rotation: only the rotation of the surface frame (IDWarp's form)"))
    rotation_reach: float | None = field(default=0.5, metadata=_doc(
        "the local-frame part of the motion (F - I or R - I, see carry) fades with distance r "
        "from each surface node as "
        "1 / (1 + (r / rho)^4), rho = rotation_reach x the mean chord (surface area / (2 x the "
        "diagonal of its bounding box)), "
        "so no node is carried further than the surface motion near it explains; null: no fade "
        "(IDWarp)"))
    tolerance: float = field(default=1e-3, metadata=_doc(
        "tree approximation: groups of far surface nodes are aggregated so that the error is about "
        "tolerance x the largest surface displacement (0 = exact sum over every surface node)"))
    fixed: tuple[str, ...] | None = field(default=None, metadata=_doc(
        "markers whose nodes never move (default: every marker that is not sliding)"))
    sliding: tuple[str, ...] | None = field(default=None, metadata=_doc(
        "planar markers whose nodes move only in their plane (default: planar markers that "
        "touch the surface, e.g. a symmetry plane)"))
    wall_layer: str = field(default="rigid", metadata=_doc(
        "rigid (default): on a mesh whose first cells are thin against the wall spacing (a RANS "
        "mesh, found from the mesh), the near-wall layer moves rigidly with its wall (the first-cell "
        "height and the off-wall angle kept) and blends into the warp beyond it; none: the warp alone"))
    chunk: int = field(default=65536, metadata=_doc(
        "volume nodes per chunk (progress and memory granularity)"))

    def __post_init__(self):
        for name in ("fixed", "sliding"):
            v = getattr(self, name)
            if v is None:
                continue
            if isinstance(v, str):
                v = (v,)
            try:
                v = tuple(str(s) for s in v)
            except TypeError:
                raise InputError(f"expected a list of marker names, got {v!r}",
                                 key=f"volume.{name}") from None
            object.__setattr__(self, name, v)
        if self.carry not in CARRY:
            raise InputError(f"expected one of {', '.join(CARRY)}, got {self.carry!r}",
                             key="volume.carry")
        if self.wall_layer not in WALL_LAYER:
            raise InputError(f"expected one of {', '.join(WALL_LAYER)}, got {self.wall_layer!r}",
                             key="volume.wall_layer")
        if self.method not in METHODS:
            raise InputError(f"expected one of {', '.join(METHODS)}, got {self.method!r}",
                             key="volume.method")
        for name in ("a", "b", "alpha"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise InputError(f"expected a positive number, got {v!r}", key=f"volume.{name}")
        if self.b < self.a:
            raise InputError(f"b ({self.b}) must be at least a ({self.a}): the b term is the "
                             "short-range one", key="volume.b")
        if self.ldef is not None and (not isinstance(self.ldef, (int, float))
                                      or not math.isfinite(self.ldef) or self.ldef <= 0):
            raise InputError(f"expected a positive length, got {self.ldef!r}", key="volume.ldef")
        rr = self.rotation_reach
        if rr is not None and (isinstance(rr, bool) or not isinstance(rr, (int, float))
                               or not math.isfinite(rr) or rr <= 0):
            raise InputError(f"expected a positive number or null, got {rr!r}",
                             key="volume.rotation_reach")
        t = self.tolerance
        if not isinstance(t, (int, float)) or not math.isfinite(t) or t < 0:
            raise InputError(f"expected a number >= 0, got {t!r}", key="volume.tolerance")
        if not isinstance(self.chunk, int) or self.chunk < 1:
            raise InputError(f"expected a positive integer, got {self.chunk!r}", key="volume.chunk")
        both = set(self.fixed or ()) & set(self.sliding or ())
        if both:
            raise InputError(f"marker(s) {', '.join(sorted(both))} named both fixed and sliding",
                             key="volume")

    @classmethod
    def field_docs(cls) -> dict[str, str]:
        """``{field name: one-line description}`` for the design-file schema."""
        return {f.name: f.metadata["doc"] for f in fields(cls)}

    @classmethod
    def from_dict(cls, d: dict | None, path=None, *, key: str = "volume") -> WarpSettings:
        """Settings from the design file's ``volume:`` mapping (None or {} gives the defaults).

        Raises InputError naming ``path`` and the key path (``volume.a``) for an unknown key or a
        bad value. Integers are accepted for the float fields; booleans are not numbers here.
        """
        if d is None:
            return cls()
        if not isinstance(d, dict):
            raise InputError(f"expected a mapping of volume-mesh settings, got {type(d).__name__}",
                             path=path, key=key)
        names = [f.name for f in fields(cls)]
        kw = {}
        for k, v in d.items():
            if k in GATE_KEYS:          # the quality gate's, in the same block
                continue
            if k not in names:
                raise InputError(f"unknown key {k!r}; expected one of {', '.join(names + list(GATE_KEYS))}",
                                 path=path, key=f"{key}.{k}")
            if isinstance(v, bool) and k not in ("fixed", "sliding"):
                kind = "name" if k in ("method", "carry", "wall_layer") else "number"
                raise InputError(f"expected a {kind}, got {v!r}",
                                 path=path, key=f"{key}.{k}")
            if k in ("fixed", "sliding") and v is not None:
                if isinstance(v, str):
                    v = [v]
                if not isinstance(v, (list, tuple)) or not all(isinstance(s, str) for s in v):
                    raise InputError(f"expected a list of marker names, got {v!r}", path=path,
                                     key=f"{key}.{k}")
            if k in ("a", "b", "alpha", "ldef", "rotation_reach", "tolerance") and isinstance(v, int):
                v = float(v)
            kw[k] = v
        try:
            return cls(**kw)
        except InputError as e:
            sub = e.key[len("volume"):] if e.key and e.key.startswith("volume") else ""
            raise InputError(e.message, path=path, key=key + sub, hint=e.hint) from None

    @classmethod
    def schema(cls) -> dict:
        """JSON-schema fragment of the design file's ``volume:`` block: THE one schema of it.

        Every :class:`WarpSettings` field and the quality gate's keys (:data:`GATE_KEYS`, read by
        :mod:`ffdcli.quality.gate` through :mod:`ffdcli.app.pipeline`); the design-file schema uses this."""
        doc = cls.field_docs()
        def names():
            return {"anyOf": [{"type": "string", "minLength": 1},
                              {"type": "array", "items": {"type": "string", "minLength": 1}}]}

        pos = {"type": "number", "exclusiveMinimum": 0}
        props = {
            "method": {"enum": list(METHODS), "default": "idw"},
            "carry": {"enum": list(CARRY), "default": "gradient"},
            "wall_layer": {"enum": list(WALL_LAYER), "default": "rigid"},
            "a": {**pos, "default": 3},
            "b": {**pos, "default": 5},
            "alpha": {**pos, "default": 1},
            "ldef": {"type": ["number", "null"], "exclusiveMinimum": 0},
            "rotation_reach": {"type": ["number", "null"], "exclusiveMinimum": 0, "default": 0.5},
            "tolerance": {"type": "number", "minimum": 0, "default": 1e-3},
            "fixed": names(),
            "sliding": names(),
            "chunk": {"type": "integer", "minimum": 1, "default": 65536},
        }
        for k, v in props.items():
            v["description"] = doc[k]
        for k, v in GATE_KEYS.items():
            props[k] = dict(v)
        return {"type": "object", "description": "How the volume mesh follows the surface "
                "(inverse-distance weighting carrying each surface node's local frame, IDWarp style) and the "
                "quality gate.",
                "properties": props, "additionalProperties": False}


#: The quality gate's keys of ``volume:`` (the gate lives in :mod:`ffdcli.quality.gate`; its default
#: threshold there is ``DEFAULT_THRESHOLD``, checked equal to this one by the tests).
GATE_KEYS = {
    "first_cell": {"type": "number", "exclusiveMinimum": 0, "default": 0.01,
                   "description": "wall layer: ffd deform warns of a design that changes the height of a "
                                  "first cell on the wall by more than 1 %; set, this tolerance is a rule: "
                                  "a design outside 1 +- it is refused, like a cell it inverts"},
    "threshold": {"type": "number", "exclusiveMinimum": 0, "maximum": 1, "default": 0.05,
                  "description": "quality gate (scaled Jacobian, 0..1): a cell below it that the "
                                 "deformation made markedly worse fails; default 0.05"},
}
