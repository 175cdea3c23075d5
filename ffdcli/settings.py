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
from dataclasses import asdict, dataclass, replace

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
    """

    points: tuple[int, ...] | None = None
    degree: tuple[int, ...] | None = None
    sections: str | None = None
    margin: float = DEFAULT_MARGIN
    root: str | None = None
    file: str | None = None

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
        return replace(self, points=pts, degree=deg)

    def as_dict(self) -> dict:
        """The settings as JSON values (tuples as lists)."""
        d = asdict(self)
        d["points"] = None if self.points is None else [int(p) for p in self.points]
        d["degree"] = None if self.degree is None else [int(q) for q in self.degree]
        d["margin"] = float(self.margin)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> BoxSettings:
        """The inverse of :meth:`as_dict`."""
        return cls(points=None if d.get("points") is None else tuple(d["points"]),
                   degree=None if d.get("degree") is None else tuple(d["degree"]),
                   sections=d.get("sections"), margin=float(d.get("margin", DEFAULT_MARGIN)),
                   root=d.get("root"), file=d.get("file"))

    def get_cache_key(self) -> str:
        """A short digest of these settings: equal settings, equal key (part of the box cache key)."""
        blob = json.dumps(self.as_dict(), sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]


# --------------------------------------------------------------------------------------------------
# WarpSettings (how the volume mesh follows the surface) comes here from ffdcli/warp.py (the `vol`
# engineer moves it): a frozen dataclass with checked()/as_dict()/get_cache_key() like BoxSettings.
# --------------------------------------------------------------------------------------------------
