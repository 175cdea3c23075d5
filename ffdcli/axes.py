"""Which mesh axis is chord, thickness and span, and which end of the span is the root.

SPEC: ``sections: xy`` means the airfoil sections lie in the x-y plane with chord along x and
thickness along y, so span is z. By default the axes are detected from the wing surface:
span = largest extent, thickness = smallest, chord = the one left (3D); in 2D the mesh plane
holds chord (larger extent of the airfoil) and thickness, and "span" is the normal of the plane.
The root is the end of the span axis closer to span coordinate 0 (a half-wing's symmetry plane).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ffdcli.errors import InputError

AXIS_NAMES = ("x", "y", "z")
SECTION_CHOICES = ("xy", "xz", "yz", "yx", "zx", "zy")
#: Two extents closer than this ratio make the detection ambiguous (reported as a guess).
AMBIGUOUS_RATIO = 1.15


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


def detect_axes(surface_points: np.ndarray, dim: int = 3, *, sections: str | None = None,
                root: str | None = None, path=None) -> Axes:
    """Axes of a wing (``dim`` 3) or airfoil (``dim`` 2) from its surface points (N, 3).

    ``sections`` and ``root`` override the detection. In 2D the root is always ``"min"``.
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
        guessed = _close(ext[span], ext[chord]) or _close(ext[chord], ext[thick])
    if root is None:
        root = "min" if dim == 2 or abs(lo[span]) <= abs(hi[span]) else "max"
    elif root not in ("min", "max"):
        raise InputError(f"expected 'min' or 'max', got {root!r}", key="root", path=path)
    return Axes(chord=chord, thickness=thick, span=span, root=root, guessed=guessed)


def _close(a: float, b: float) -> bool:
    a, b = abs(float(a)), abs(float(b))
    return max(a, b) <= AMBIGUOUS_RATIO * min(a, b) if min(a, b) > 0 else a == b
