"""Shape: control points move along the thickness axis."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ffdcli.errors import InputError
from ffdcli.parameterization.changes.base import (
    CHANGES,
    Change,
    SpecContext,
)
from ffdcli.schema_parts import number_list


@dataclass(frozen=True, eq=False)
class Shape(Change):
    """Move control points along each section's own thickness direction (mesh units).

    The direction of section ``j`` is read off the input lattice (:func:`section_normals`): the sum
    of its thickness edges ``P[i, j, l-1] - P[i, j, 0]`` over ``i``, normalised and oriented along
    the frame's thickness axis. A section turned by a twist before the shape moves along its turned
    thickness axis (a twisted section's shape change is the untwisted one turned by the twist), and
    a shape does not turn the direction it moves along (it adds to every edge along it). A box
    fitted to a twisted wing has sections aligned with the local chord: there too a shape moves
    normal to the local chord line. (pyGeo's convention is the box's one thickness axis for every
    section.)

    upper, lower
        (n,) one value per chordwise index for the upper (k = l-1) / lower (k = 0) row of every
        section in ``sections``; or (n, m) one value per point and section (a random shape
        expanded at load time; ``sections`` is then ignored). ``None``: that side does not move.
    sections
        Section indices, or None for all sections.
    rows
        (l, n) one value per thickness row k (0 = lower ... l-1 = upper) and chordwise index i, for
        every section in ``sections`` (an extension: ``ffd fit --rows all`` moves every row).
    Variables: ``shape.upper[i]`` / ``shape.lower[i]``; for (n, m) arrays ``shape.upper[i,j]``;
    ``shape.rows[k][i]``.
    """

    upper: np.ndarray | None = None
    lower: np.ndarray | None = None
    sections: tuple[int, ...] | None = None
    rows: np.ndarray | None = None
    kind = "shape"

    @classmethod
    def schema(cls) -> dict:
        return {"description": "{upper: [one per chordwise point], lower: [...], sections: all | [j, ...]}"
                               " or {random: A, seed: S}",
                "type": "object",
                "properties": {
                    "upper": number_list(), "lower": number_list(),
                    "rows": {"description": "extension: one list per thickness row (lower first, "
                                            "l lists of n values), instead of upper/lower",
                             "type": "array", "items": number_list(), "minItems": 2},
                    "sections": {"description": "all, or a list of section indices",
                                 "anyOf": [{"const": "all"},
                                           {"type": "array", "items": {"type": "integer", "minimum": 0},
                                            "minItems": 1}]},
                    "random": {"type": "number", "minimum": 0},
                    "seed": {"type": "integer", "minimum": 0}},
                "additionalProperties": False,
                "anyOf": [{"required": ["upper"]}, {"required": ["lower"]}, {"required": ["random"]},
                          {"required": ["rows"]}]}

    @classmethod
    def from_spec(cls, spec, ctx: SpecContext) -> Shape:
        """``{upper: [n], lower: [n], sections: all | [j, ...]}``, ``{rows: [l lists of n]}`` or
        ``{random: A, seed: S}`` (``default_rng(S).uniform(-A, A, size=(2, n, m))``: upper, lower)."""
        n, m, l, key = ctx.n, ctx.m, ctx.l, ctx.key
        if "random" in spec:
            rng = np.random.default_rng(int(spec.get("seed", 0)))
            try:
                upper, lower = rng.uniform(-spec["random"], spec["random"], size=(2, n, m))
            except OverflowError:
                raise ctx.fail(f"{spec['random']:g} is too large for a uniform draw", key + ".random") from None
            return cls(upper, lower)
        for side in ("upper", "lower"):
            if side in spec and len(spec[side]) != n:
                raise ctx.fail(f"has {len(spec[side])} values but the box has {n} chordwise points "
                               "(box.points[0])", f"{key}.{side}")
        sections = spec.get("sections", "all")
        if sections == "all":
            sections = None
        else:
            for q, j in enumerate(sections):
                if not 0 <= j < m:
                    raise ctx.fail(f"section {j} does not exist: sections run from 0 (root) to {m - 1}",
                                   f"{key}.sections[{q}]")
        rows = spec.get("rows")
        if rows is not None:
            if len(rows) != l:
                raise ctx.fail(f"has {len(rows)} rows but the box has {l} thickness points (box.points[-1])",
                               f"{key}.rows")
            for k, row in enumerate(rows):
                if len(row) != n:
                    raise ctx.fail(f"has {len(row)} values but the box has {n} chordwise points "
                                   "(box.points[0])", f"{key}.rows[{k}]")
        return cls(spec.get("upper"), spec.get("lower"), sections, rows=rows)

    def __post_init__(self):
        for side in ("upper", "lower"):
            v = getattr(self, side)
            if v is not None:
                v = np.array(v, dtype=float)
                if v.ndim not in (1, 2):
                    raise ValueError(f"shape.{side} must have shape (n,) or (n, m)")
                object.__setattr__(self, side, v)
        if self.rows is not None:
            r = np.array(self.rows, dtype=float)
            if r.ndim != 2:
                raise ValueError("shape.rows must have shape (l, n)")
            object.__setattr__(self, "rows", r)
        if self.upper is None and self.lower is None and self.rows is None:
            raise ValueError("shape: give upper, lower or both (or rows)")
        if self.sections is not None:
            object.__setattr__(self, "sections", tuple(int(j) for j in self.sections))

    def _sides(self):
        out = [(side, k, getattr(self, side)) for side, k in (("upper", -1), ("lower", 0))
               if getattr(self, side) is not None]
        if self.rows is not None:
            out += [(f"rows[{k}]", k, row) for k, row in enumerate(self.rows)]
        return out

    def _check(self, P):
        n, m = P.shape[0], P.shape[1]
        if self.rows is not None and self.rows.shape != (P.shape[2], n):
            raise InputError(f"shape.rows has shape {self.rows.shape} but the lattice has l={P.shape[2]}, n={n}")
        for side, _, v in self._sides():
            if v.shape[0] != n or (v.ndim == 2 and v.shape[1] != m):
                raise InputError(f"shape.{side} has shape {v.shape} but the lattice has n={n}, m={m}")
        if self.sections is not None and any(not 0 <= j < m for j in self.sections):
            raise InputError(f"shape.sections {list(self.sections)}: section indices run from 0 to {m - 1}")

    def _cols(self, m):
        return list(range(m)) if self.sections is None else list(self.sections)

    def amounts(self, P) -> np.ndarray:
        """(n, m, l) displacement of every control point along the thickness axis."""
        self._check(P)
        n, m, l, _ = P.shape
        a = np.zeros((n, m, l))
        for _, k, v in self._sides():
            if v.ndim == 2:
                a[:, :, k] += v
            else:
                a[:, self._cols(m), k] += v[:, None]
        return a

    def apply(self, P, frame):
        return P + self.amounts(P)[..., None] * per_point(section_normals(P, frame))

    def variables(self):
        out = []
        for side, _, v in self._sides():
            if v.ndim == 2:
                out += [(f"shape.{side}[{i},{j}]", float(v[i, j]))
                        for i in range(v.shape[0]) for j in range(v.shape[1])]
            else:
                out += [(f"shape.{side}[{i}]", float(x)) for i, x in enumerate(v)]
        return out

    def with_values(self, values):
        vals = np.asarray(values, dtype=float).reshape(-1)
        if vals.size != self.size:
            raise ValueError(f"shape: expected {self.size} values, got {vals.size}")
        new, at = {}, 0
        rows = None if self.rows is None else self.rows.copy()
        for side, k, v in self._sides():
            if side.startswith("rows["):
                rows[k] = vals[at:at + v.size]
            else:
                new[side] = vals[at:at + v.size].reshape(v.shape)
            at += v.size
        if rows is not None:
            new["rows"] = rows
        return replace(self, **new)

    def jacobian_own(self, P, frame):
        self._check(P)
        n, m, l, _ = P.shape
        J = np.zeros((self.size, n, m, l, 3))
        t = section_normals(P, frame)
        q = 0
        for _, k, v in self._sides():
            if v.ndim == 2:
                for i in range(v.shape[0]):
                    for j in range(v.shape[1]):
                        J[q, i, j, k] = t[j]
                        q += 1
            else:
                cols = self._cols(m)
                for i in range(v.shape[0]):
                    J[q, i, cols, k] = t[cols]
                    q += 1
        return J

    def jvp_P(self, P, frame, dP):
        """dP + a dt_j: the sections' directions turn with the lattice."""
        dP = np.asarray(dP, dtype=float)
        dt = section_normals_jvp(P, frame, dP)
        return dP + self.amounts(P)[..., None] * dt[..., None, :, None, :]


#: A section direction within this of the frame's thickness axis is that axis (so that an untwisted
#: box's shapes move exactly along it, bit for bit as before the directions were per section).
SAME_DIRECTION = 1e-13


def _edges(P: np.ndarray) -> np.ndarray:
    """(..., m, 3) the sum over i of the thickness edges ``P[i, j, l-1] - P[i, j, 0]``."""
    return (P[..., :, :, -1, :] - P[..., :, :, 0, :]).sum(axis=-3)


def section_normals(P: np.ndarray, frame) -> np.ndarray:
    """(m, 3) each section's own unit thickness direction in the lattice ``P`` (n, m, l, 3): its
    summed thickness edges, normalised, on the side of ``frame.thickness_dir``; a lattice of one
    thickness row (l = 1) has the frame's."""
    m = P.shape[1]
    t0 = frame.thickness_dir
    if P.shape[2] < 2:
        return np.broadcast_to(t0, (m, 3)).copy()
    v = _edges(P)
    v = v * np.sign(v @ t0)[:, None]
    t = v / np.linalg.norm(v, axis=1)[:, None]
    same = np.abs(t - t0).max(axis=1) < SAME_DIRECTION
    t[same] = t0
    return t


def section_normals_jvp(P: np.ndarray, frame, dP: np.ndarray) -> np.ndarray:
    """(..., m, 3) the change of :func:`section_normals` for a change ``dP`` (..., n, m, l, 3)."""
    if P.shape[2] < 2:
        return np.zeros(dP.shape[:-4] + (P.shape[1], 3))
    v = _edges(P)
    sgn = np.sign(v @ frame.thickness_dir)
    norm = np.linalg.norm(v, axis=1)
    t = v * sgn[:, None] / norm[:, None]
    dv = _edges(dP) * sgn[:, None]
    return (dv - np.einsum("...j,jd->...jd", np.einsum("...jd,jd->...j", dv, t), t)) / norm[:, None]


def per_point(t: np.ndarray) -> np.ndarray:
    """(1, m, 1, 3): per-section vectors (m, 3) broadcast over a lattice."""
    return t[None, :, None, :]


CHANGES.register(Shape)
