"""Which mesh axis is chord, thickness and span, and which end of the span is the root.

SPEC: ``sections: xy`` means the airfoil sections lie in the x-y plane with chord along x and
thickness along y, so span is z. By default the axes are detected from the wing surface (3D):

1. thickness = the smallest extent;
2. span: when the surface is open at its root (a half-wing cut by its symmetry plane, a wing or a fin
   on a body), the nodes of its free edges (edges of one face only) lie in the root plane, flat at one
   end of the span axis. The axis, other than the thickness, along which clearly most free-edge nodes
   sit exactly at one end of the surface's extent (within :data:`PLANE_TOL` of it) is the span, and
   that end is the root. This tells a swept low-aspect-ratio wing or a fin (chord and span extents
   alike: the ONERA M6, a tail) from a long chord.
3. otherwise span = the largest extent, chord = the one left, and the root is the end of the span
   axis closer to span coordinate 0 (a half-wing's symmetry plane); extents within
   :data:`AMBIGUOUS_RATIO` of each other are reported as a guess.

In 2D the mesh plane holds chord (larger extent of the airfoil) and thickness, and "span" is the
normal of the plane.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.errors import InputError
from ffdcli.mesh.idsets import unique_ids
from ffdcli.settings import SECTION_CHOICES

AXIS_NAMES = ("x", "y", "z")
#: Two extents closer than this ratio make the detection ambiguous (reported as a guess).
AMBIGUOUS_RATIO = 1.15
#: A free-edge node lies in an end plane when within this fraction of the surface's largest extent.
PLANE_TOL = 1e-6
#: The root plane needs at least this many free-edge nodes, and this many times more than any other end.
ROOT_MIN_NODES, ROOT_DOMINANCE = 6, 2.0


@dataclass(frozen=True)
class Axes:
    """Column indices (0 = x, 1 = y, 2 = z) of the chord, thickness and span axes.

    ``root`` is ``"min"`` or ``"max"``: the end of the span axis where the root section is.
    ``guessed`` is True when the detection could not tell the axes apart clearly.
    """

    chord: int
    thickness: int
    span: int
    root: str = "min"
    guessed: bool = False

    def __post_init__(self):
        if sorted((self.chord, self.thickness, self.span)) != [0, 1, 2]:
            raise ValueError(f"axes must be a permutation of 0, 1, 2: {self}")
        if self.root not in ("min", "max"):
            raise ValueError(f"root must be 'min' or 'max', got {self.root!r}")

    @property
    def sections(self) -> str:
        """The ``sections`` setting that gives these axes, e.g. ``"xy"``."""
        return AXIS_NAMES[self.chord] + AXIS_NAMES[self.thickness]

    @property
    def span_sign(self) -> float:
        """+1 if the span grows from root to tip along +axis, -1 otherwise."""
        return 1.0 if self.root == "min" else -1.0

    def as_dict(self) -> dict:
        """``{"chord": "x", "thickness": "z", "span": "y"}`` as in the ``--json`` summaries."""
        return {"chord": AXIS_NAMES[self.chord], "thickness": AXIS_NAMES[self.thickness],
                "span": AXIS_NAMES[self.span]}


def parse_sections(sections: str, *, key: str = "sections", path=None) -> tuple[int, int, int]:
    """``"xy"`` -> (chord, thickness, span) = (0, 1, 2). Raises InputError for anything else."""
    s = str(sections).strip().lower()
    if s not in SECTION_CHOICES:
        raise InputError(f"expected one of {', '.join(SECTION_CHOICES)}, got {sections!r}",
                         key=key, path=path)
    chord, thick = AXIS_NAMES.index(s[0]), AXIS_NAMES.index(s[1])
    return chord, thick, 3 - chord - thick


def free_edge_nodes(faces, n_points: int) -> np.ndarray:
    """Sorted ids of the nodes on free edges (edges of exactly one face) of ``faces`` (CellBlocks)."""
    edges = []
    for block in faces:
        c = np.asarray(block.data, dtype=np.int64)
        if c.ndim != 2 or c.shape[1] < 3:
            continue
        e = np.stack([c, np.roll(c, -1, axis=1)], axis=-1).reshape(-1, 2)
        edges.append(e[e[:, 0] != e[:, 1]])               # collapsed quads repeat a node
    if not edges:
        return np.zeros(0, dtype=np.int64)
    e = np.sort(np.concatenate(edges), axis=1)
    key, count = np.unique(e[:, 0] * np.int64(n_points) + e[:, 1], return_counts=True)
    free = key[count == 1]
    return unique_ids(free // n_points, free % n_points)


def root_plane(points: np.ndarray, faces, thickness: int) -> tuple[int, str] | None:
    """(span axis, root end ``"min"``/``"max"``) from the free edges of the surface, or None.

    See the module docstring (rule 2). ``thickness`` is excluded: a sharp trailing edge whose upper
    and lower nodes are not shared is a free edge flat along the thickness."""
    ids = free_edge_nodes(faces, len(points))
    if len(ids) < ROOT_MIN_NODES:
        return None
    lo, hi = points.min(axis=0), points.max(axis=0)
    tol = PLANE_TOL * float((hi - lo).max())
    q = points[ids]
    counts = {}
    for a in range(3):
        if a == thickness:
            continue
        counts[(a, "min")] = int(np.count_nonzero(np.abs(q[:, a] - lo[a]) <= tol))
        counts[(a, "max")] = int(np.count_nonzero(np.abs(q[:, a] - hi[a]) <= tol))
    best = max(counts, key=counts.get)
    rest = max(v for k, v in counts.items() if k != best)
    if counts[best] < ROOT_MIN_NODES or counts[best] < ROOT_DOMINANCE * rest:
        return None
    return best


def detect_axes(surface_points: np.ndarray, dim: int = 3, *, sections: str | None = None,
                root: str | None = None, path=None, faces=None) -> Axes:
    """Axes of a wing (``dim`` 3) or airfoil (``dim`` 2) from its surface points (N, 3).

    ``faces`` (CellBlocks of local point ids) lets the root plane tell the span axis (module
    docstring, rule 2). ``sections`` and ``root`` override the detection. In 2D the root is always
    ``"min"``.
    """
    pts = np.asarray(surface_points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
        raise InputError("the surface has no points", path=path)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    ext = hi - lo
    guessed = False
    if sections is not None:
        chord, thick, span = parse_sections(sections, path=path)
    elif dim == 2:
        span = int(np.argmin(ext))                      # the plane normal: (near) zero extent
        rest = [a for a in range(3) if a != span]
        chord, thick = sorted(rest, key=lambda a: -ext[a])
        guessed = _close(ext[chord], ext[thick])
    else:
        order = np.argsort(-ext, kind="stable")         # largest first
        span, chord, thick = int(order[0]), int(order[1]), int(order[2])
        plane = root_plane(pts, faces, thick) if faces is not None else None
        if plane is not None:
            span = plane[0]
            chord = 3 - span - thick
            root = plane[1] if root is None else root
            guessed = _close(ext[chord], ext[thick])
        else:
            guessed = _close(ext[span], ext[chord]) or _close(ext[chord], ext[thick])
    if root is None:
        root = "min" if dim == 2 or abs(lo[span]) <= abs(hi[span]) else "max"
    elif root not in ("min", "max"):
        raise InputError(f"expected 'min' or 'max', got {root!r}", key="root", path=path)
    return Axes(chord=chord, thickness=thick, span=span, root=root, guessed=guessed)


def _close(a: float, b: float) -> bool:
    a, b = abs(float(a)), abs(float(b))
    return max(a, b) <= AMBIGUOUS_RATIO * min(a, b) if min(a, b) > 0 else a == b
