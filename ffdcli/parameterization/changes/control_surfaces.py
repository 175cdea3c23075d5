"""Control surfaces: a flap (trailing-edge device) or a slat (leading-edge device) that turns about
its hinge line, the surface staying one piece (a morphing device).

The part of the lattice behind the hinge (a flap) or ahead of it (a slat), between two span
fractions, turns by ``angle`` degrees about the hinge line: the straight line through the hinge
points at the device's two ends (chord fraction ``hinge`` of the local baseline chord there, at
mid-thickness). Positive: trailing edge down (flap), leading edge down (slat). Which control
points turn, and the knots that make the device sharp, are in :mod:`.devices`; here the map:

    x' = H + R(omega, theta_j) (x - H)    for the turning rows i of section j, x' = x elsewhere,

``theta_j = angle * weights[j]`` (weights 1 for the sections in the device's span, 0 outside it and
its blends, a straight ramp across each blend: :func:`.devices.section_weights`), ``H`` the inner
hinge point, ``omega`` the unit hinge direction
signed so that a positive angle moves the trailing edge (flap) or leading edge (slat) down, and
``R`` Rodrigues' rotation. The hinge points are basis rows applied to the input lattice, so the
device follows the changes before it.

A hinge given as a list (two fractions; one in 2D) is a design variable. Its lattice is made from its
``hinge_range`` and never from its value (:mod:`.hinge_ramp`), so that ``ffd deform`` at any value and
the derivatives at any value see one lattice: the hinge point moves along the local chord, and row
``i`` of section ``j`` turns by ``theta_ij = angle * w_ij(hinge) * weights[j]``, ``w`` the ramp's share
(:meth:`.hinge_ramp.HingeRamp.weights`: none ahead of the hinge, all of it behind the transition).
A fixed hinge (one number) keeps its knots at the hinge (``w`` is 1 on the rows behind it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ffdcli.box.refine import refine_box, refine_embedding
from ffdcli.errors import InputError
from ffdcli.parameterization.changes.base import CHANGES, DEG, Change, SpecContext
from ffdcli.parameterization.changes.devices import (
    DEFAULT_BLEND,
    DEFAULT_TRANSITION,
    HINGE_RANGE,
    MAX_ANGLE,
    DeviceGeometry,
    DeviceSpec,
    blend_widths,
    device_geometry,
    device_knots,
)
from ffdcli.schema_parts import number


def skew(w: np.ndarray) -> np.ndarray:
    """(..., 3, 3) the cross-product matrices of vectors ``w`` (..., 3): ``skew(w) @ x = w x x``."""
    w = np.asarray(w, dtype=float)
    K = np.zeros(w.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -w[..., 2], w[..., 1]
    K[..., 1, 0], K[..., 1, 2] = w[..., 2], -w[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -w[..., 1], w[..., 0]
    return K


def rodrigues(omega: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """(m, 3, 3) rotations by ``theta`` (m,) radians about the unit axis ``omega`` (3,)."""
    K = skew(omega)
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def rodrigues_dtheta(omega: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """(m, 3, 3) d :func:`rodrigues` / d theta (per radian)."""
    K = skew(omega)
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return c * K + s * (K @ K)


def rodrigues_domega(omega: np.ndarray, theta: np.ndarray, domega: np.ndarray) -> np.ndarray:
    """(..., m, 3, 3) the derivative of :func:`rodrigues` along ``domega`` (..., 3)."""
    K = skew(omega)
    dK = skew(domega)[..., None, :, :]
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return s * dK + (1.0 - c) * (dK @ K + K @ dK)


@dataclass(frozen=True, eq=False)
class ControlSurface(Change):
    """A flap or slat (see the module docstring).

    angle
        Degrees; positive: trailing edge (flap) or leading edge (slat) down.
    hinge
        Chord fractions at the inner and outer end (one number in 2D, or the same at both ends).
    hinge_variable
        The hinge fractions are design variables (``hinge[0]``, ``hinge[1]``; given as a list of two).
    geometry
        The device's :class:`~ffdcli.parameterization.changes.devices.DeviceGeometry` in the lattice.
    spec
        The device as written (span range, blend, transition).
    """

    angle: float
    hinge: tuple[float, ...]
    geometry: DeviceGeometry
    spec: DeviceSpec
    hinge_variable: bool = False
    kind = "flap"
    unit = "deg"

    @classmethod
    def from_spec(cls, spec, ctx: SpecContext) -> ControlSurface:
        """``{span: [a, b], hinge: h | [h_inner, h_outer], angle: A, blend: w, transition: c}``
        (3D; 2D: no span, no blend). Needs the box (``ctx.box``)."""
        dspec = parse_device(cls.kind, spec, ctx)
        if ctx.box is None:
            raise ctx.fail(f"a {cls.kind} needs the box it acts in")
        geometry = device_geometry(ctx.box, ctx.surface, dspec)
        return cls(angle=float(spec["angle"]), hinge=dspec.hinge, geometry=geometry, spec=dspec,
                   hinge_variable=isinstance(spec["hinge"], list))

    # ------------------------------------------------------------------ variables
    def variables(self):
        out = [(f"{self.kind}.angle", float(self.angle))]
        if self.hinge_variable:
            out += [(f"{self.kind}.hinge[{e}]", float(h)) for e, h in enumerate(self.hinge)]
        return out

    def units(self):
        return ["deg"] + ["factor"] * (self.size - 1)

    def with_values(self, values):
        v = np.asarray(values, dtype=float).reshape(-1)
        if v.size != self.size:
            raise ValueError(f"{self.kind}: expected {self.size} values, got {v.size}")
        hinge = tuple(float(h) for h in v[1:]) if self.hinge_variable else self.hinge
        return replace(self, angle=float(v[0]), hinge=hinge)

    def bounds(self, P, frame):
        """The angle within +-:data:`MAX_ANGLE` degrees (what a design file may give), a hinge fraction
        within its ``hinge_range`` (the lattice has knots there only)."""
        lo, hi = self.spec.hinge_range if self.spec.hinge_range is not None else (0.0, 1.0)
        return np.array([[-MAX_ANGLE, MAX_ANGLE]] + [[lo, hi]] * (self.size - 1))

    # ------------------------------------------------------------------ the map
    def _hinges(self, P) -> tuple[np.ndarray, np.ndarray]:
        """(..., E, 3) hinge points of ``P`` (..., n, m, l, 3) and (..., E, 3) local chord vectors."""
        g = self.geometry
        flat = P.reshape(*P.shape[:-4], -1, 3)
        M = np.einsum("eq,...qd->...ed", g.M, flat)
        D = np.einsum("eq,...qd->...ed", g.T - g.L, flat)
        dh = np.asarray(self.hinge, dtype=float) - g.hinge0
        return M + dh[:, None] * D, D

    def _axis(self, H, frame) -> tuple[np.ndarray, float, np.ndarray]:
        """(omega (3,), sign, v (3,)): the unit hinge axis, its sign along the hinge line and the
        hinge line vector (zero in 2D)."""
        normal = np.cross(frame.chord_dir, frame.thickness_dir)
        down = 1.0 if self.kind == "flap" else -1.0          # omega x chord = -down * thickness
        if frame.dim == 2 or len(H) == 1:
            return -down * normal, 0.0, np.zeros(3)
        v = H[1] - H[0]
        d = v / np.linalg.norm(v)
        along = float(d @ normal)
        if abs(along) < 1e-6:
            raise ValueError(f"the {self.kind}'s hinge line is along the chord")
        sign = -down * math.copysign(1.0, along)
        return sign * d, sign, v

    def _shares(self) -> tuple[np.ndarray, np.ndarray | None]:
        """(n, m) the share of the angle each row and section turns by and (E, n, m) its derivative by
        the hinge fractions (None: a fixed hinge)."""
        g = self.geometry
        if g.ramp is None:
            return g.rows[:, None] * g.weights[None, :], None
        w, dw = g.ramp.weights(self.hinge)
        return w * g.weights, dw * g.weights

    def apply(self, P, frame):
        H, _ = self._hinges(P)
        omega, _, _ = self._axis(H, frame)
        theta = self.angle * DEG * self._shares()[0]
        out = np.array(P, dtype=float, copy=True)
        # only the rows and sections that turn (a 0 degree device is no change, bit for bit)
        turn = theta != 0.0
        i, j = np.flatnonzero(turn.any(axis=1)), np.flatnonzero(turn.any(axis=0))
        th = theta[np.ix_(i, j)]
        R = rodrigues(omega, th.reshape(-1)).reshape(th.shape + (3, 3))
        Y = P[np.ix_(i, j)] - H[0]
        out[np.ix_(i, j)] = H[0] + np.einsum("ijab,ijkb->ijka", R, Y)
        return out

    def _domega(self, H, v, sign, dH):
        """(..., 3) the change of the unit axis for hinge-point changes dH (..., E, 3)."""
        d = v / np.linalg.norm(v)
        dv = dH[..., 1, :] - dH[..., 0, :]
        return sign * (dv - (dv @ d)[..., None] * d) / np.linalg.norm(v)

    def _hinge_motion(self, P, frame, rows, theta, dH, dY):
        """dP' of the turning ``rows`` (turning by ``theta`` (rows, m)) for hinge-point changes dH
        (..., E, 3) and point changes dY (..., rows, m, l, 3): (I - R) dH0 + R dY + dR[domega] (x - H0)."""
        H, _ = self._hinges(P)
        omega, sign, v = self._axis(H, frame)
        R = rodrigues(omega, theta.reshape(-1)).reshape(theta.shape + (3, 3))
        out = np.einsum("ijab,...ijkb->...ijka", R, dY - dH[..., 0, None, None, None, :]) \
            + dH[..., 0, None, None, None, :]
        if frame.dim == 3 and len(H) == 2:
            dw = self._domega(H, v, sign, dH)
            dR = rodrigues_domega(omega, theta.reshape(-1), dw).reshape(dw.shape[:-1] + theta.shape + (3, 3))
            out = out + np.einsum("...ijab,ijkb->...ijka", dR, P[rows] - H[0])
        return out

    def jacobian_own(self, P, frame):
        H, D = self._hinges(P)
        omega, _, _ = self._axis(H, frame)
        W, dW = self._shares()
        rows = W.any(axis=1)
        theta = self.angle * DEG * W[rows]
        J = np.zeros((self.size,) + P.shape)
        th = theta.reshape(-1)
        dR = rodrigues_dtheta(omega, th).reshape(theta.shape + (3, 3))
        X = P[rows] - H[0]
        J[0][rows] = np.einsum("ijab,ijkb->ijka", dR * (DEG * W[rows])[..., None, None], X)
        if self.hinge_variable:
            for e in range(len(self.hinge)):
                dH = np.zeros(H.shape)
                dH[e] = D[e]
                J[1 + e][rows] = self._hinge_motion(P, frame, rows, theta, dH, np.zeros(P[rows].shape))
                if dW is not None:     # the share of the angle moves with the hinge
                    J[1 + e][rows] += np.einsum("ijab,ijkb->ijka",
                                                dR * (self.angle * DEG * dW[e][rows])[..., None, None], X)
        return J

    def jvp_P(self, P, frame, dP):
        dP = np.asarray(dP, dtype=float)
        out = np.array(dP, copy=True)
        dH, _ = self._hinges(dP)          # the hinge points are linear in the lattice
        W, _ = self._shares()
        rows = W.any(axis=1)
        out[..., rows, :, :, :] = self._hinge_motion(P, frame, rows, self.angle * DEG * W[rows], dH,
                                                     dP[..., rows, :, :, :])
        return out

    def describe(self) -> dict:
        """What ``ffd deform`` prints: the device as set up, and the chord width of the transition
        behind (flap; slat: ahead of) the hinge, after which the device turns rigidly."""
        return {"kind": self.kind, "angle": float(self.angle), "hinge": [float(h) for h in self.hinge],
                "span": None if self.spec.span is None else list(self.spec.span),
                "blend": None if self.spec.span is None else self.spec.blend,
                "blends": None if self.spec.span is None else list(blend_widths(self.spec)),
                "transition": float(self.geometry.transition.max()),
                "hinge_range": None if self.spec.hinge_range is None else list(self.spec.hinge_range),
                "turning_rows": int(self.geometry.rows.sum()),
                "turning_sections": int(np.count_nonzero(self.geometry.weights))}

    def hinge_line(self, P) -> np.ndarray:
        """(E, 3) the hinge points of lattice ``P`` (for pictures)."""
        return self._hinges(P)[0]


@dataclass(frozen=True, eq=False)
class Flap(ControlSurface):
    """A trailing-edge device: the part behind the hinge turns; positive: trailing edge down."""

    kind = "flap"

    @classmethod
    def schema(cls) -> dict:
        return device_schema("trailing-edge", "trailing edge")


@dataclass(frozen=True, eq=False)
class Slat(ControlSurface):
    """A leading-edge device: the part ahead of the hinge turns; positive: leading edge down."""

    kind = "slat"

    @classmethod
    def schema(cls) -> dict:
        return device_schema("leading-edge", "leading edge")


def device_schema(part: str, down: str) -> dict:
    """The YAML of a flap or slat (``part``: trailing-edge or leading-edge)."""
    fraction = {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": 1}
    return {"description": f"a {part} device that turns about its hinge line (morphing: the surface stays "
                           f"one piece): {{span: [inner, outer], hinge: h | [h_inner, h_outer], angle: A, "
                           f"blend: w, transition: c}}; angle in degrees, positive: {down} down; hinge: "
                           "chord fraction of the local chord at each end (a list of two: design "
                           "variables); blend: span width over which the rotation fades at each end "
                           "(default 0.2); transition: chord width behind the hinge where the surface "
                           "bends (default 0.1); hinge_range: [lo, hi] the chord fractions a variable "
                           "hinge may take (the lattice is made for them; default flap [0.6, 0.85], slat "
                           "[0.1, 0.3]); in 2D no span and no blend",
            "type": "object", "additionalProperties": False, "required": ["hinge", "angle"],
            "properties": {
                "span": {"type": "array", "items": {"type": "number", "minimum": 0, "maximum": 1},
                         "minItems": 2, "maxItems": 2},
                "hinge": {"anyOf": [fraction, {"type": "array", "items": fraction, "minItems": 1,
                                               "maxItems": 2}]},
                "angle": number(),
                "blend": {"type": "number", "minimum": 0},
                "transition": {"type": "number", "exclusiveMinimum": 0},
                "hinge_range": {"type": "array", "items": fraction, "minItems": 2, "maxItems": 2}}}


def parse_device(kind: str, spec, ctx: SpecContext) -> DeviceSpec:
    """The :class:`DeviceSpec` of a ``flap``/``slat`` item, checked (clear errors at its keys)."""
    key = ctx.key
    if ctx.dim == 2:
        for bad in ("span", "blend"):
            if bad in spec:
                raise ctx.fail(f"a 2D {kind} has no {bad}: it turns the whole "
                               f"{'aft' if kind == 'flap' else 'fore'} part of the airfoil", f"{key}.{bad}")
        span = None
    else:
        if "span" not in spec:
            raise ctx.fail(f"a {kind} needs span: [inner, outer] (span fractions, root 0, tip 1)",
                           f"{key}.span")
        a, b = (float(x) for x in spec["span"])
        if not 0.0 <= a < b <= 1.0:
            raise ctx.fail(f"span [{a:g}, {b:g}]: two span fractions with 0 <= inner < outer <= 1",
                           f"{key}.span")
        span = (a, b)
    hinge = spec["hinge"]
    hinge = [hinge] if not isinstance(hinge, list) else hinge
    if isinstance(spec["hinge"], list) and len(hinge) != (2 if ctx.dim == 3 else 1):
        raise ctx.fail(f"hinge takes one chord fraction or a list of {2 if ctx.dim == 3 else 1} "
                       "(inner end, outer end)", f"{key}.hinge")
    hinge = [float(h) for h in hinge]
    if any(not 0.02 <= h <= 0.98 for h in hinge):
        raise ctx.fail(f"hinge {hinge}: chord fractions between 0.02 and 0.98", f"{key}.hinge")
    if ctx.dim == 3 and len(hinge) == 1:
        hinge = hinge * 2
    variable = isinstance(spec["hinge"], list)
    hinge_range = None
    if "hinge_range" in spec and not variable:
        raise ctx.fail("hinge_range is where a variable hinge may go: give hinge as a list "
                       f"({'[h_inner, h_outer]' if ctx.dim == 3 else '[h]'}) or leave hinge_range out",
                       f"{key}.hinge_range")
    if variable:
        lo, hi = (float(x) for x in spec.get("hinge_range", HINGE_RANGE[kind]))
        if not 0.02 <= lo < hi <= 0.98:
            raise ctx.fail(f"hinge_range [{lo:g}, {hi:g}]: two chord fractions with 0.02 <= lo < hi <= 0.98",
                           f"{key}.hinge_range")
        if any(not lo < h < hi for h in hinge):
            where = "hinge_range" if "hinge_range" in spec else f"the default hinge_range of a {kind}"
            raise ctx.fail(f"hinge {hinge}: a variable hinge lies strictly inside {where} ({lo:g}, {hi:g}) "
                           "(the lattice has its knots there, and it is the variable's bounds); give "
                           "hinge_range: [lo, hi] around it", f"{key}.hinge")
        hinge_range = (lo, hi)
    blend = float(spec.get("blend", DEFAULT_BLEND))
    if not 0.0 <= blend <= 0.5:
        raise ctx.fail(f"blend {blend:g}: a span width in [0, 0.5]", f"{key}.blend")
    # the device's chord; a variable hinge's default transition is read at the middle of its range, and
    # the transition must fit the least device chord over the range (its lattice cannot depend on the value)
    if hinge_range is None:
        part = (1.0 - min(hinge)) if kind == "flap" else max(hinge)
        default = min(DEFAULT_TRANSITION, 0.5 * part)
    else:
        middle = 0.5 * (hinge_range[0] + hinge_range[1])
        part = (1.0 - hinge_range[1]) if kind == "flap" else hinge_range[0]
        default = min(DEFAULT_TRANSITION, 0.5 * ((1.0 - middle) if kind == "flap" else middle), 0.9 * part)
    transition = float(spec.get("transition", default))
    if not 0.0 < transition <= 0.9 * part:
        raise ctx.fail(f"transition {transition:g}: a chord width in (0, {0.9 * part:.3g}] (inside the "
                       f"{kind})", f"{key}.transition")
    angle = float(spec["angle"])
    if not -MAX_ANGLE <= angle <= MAX_ANGLE:
        raise ctx.fail(f"angle {angle:g}: degrees within [-{MAX_ANGLE:g}, {MAX_ANGLE:g}]", f"{key}.angle")
    return DeviceSpec(kind=kind, span=span, hinge=tuple(hinge), blend=blend, transition=transition,
                      hinge_range=hinge_range)


def refine_for_devices(box, emb, surface, specs, error=None, key: str = "changes"):
    """The box with the knots every ``flap``/``slat`` of ``specs`` (a ``changes`` list as written)
    needs, by exact knot insertion, and the embedding ``emb`` in it (the same parameters). Without
    devices: the inputs."""
    chord, span = [], []
    dim = box.dim
    n, m, l = box.shape
    for index, item in enumerate(specs):
        (kind, spec), = item.items()
        if kind not in ("flap", "slat"):
            continue
        ctx = SpecContext(n=n, m=m, l=l, dim=dim, key=f"{key}[{index}].{kind}", error=error)
        dspec = parse_device(kind, spec, ctx)
        try:
            u, v = device_knots(box, surface, dspec)
        except InputError as e:
            raise ctx.fail(e.message) from None
        chord.extend(u)
        span.extend(v)
    if not chord:
        return box, emb
    out, _ = refine_box(box, chord=chord, span=span)
    return out, refine_embedding(out, emb)


CHANGES.register(Flap)
CHANGES.register(Slat)
