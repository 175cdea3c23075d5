"""A variable hinge: which share of a device's angle each chordwise row turns by, as a smooth
function of the hinge fractions, on a lattice that does not depend on them.

A fixed hinge puts ``p + 1`` knots from its hinge to the end of its transition
(:func:`ffdcli.parameterization.changes.devices.device_knots`): the device is sharp there. A hinge
that is a design variable cannot: the knots, hence the lattice, the embedding's basis and every
factor ``dX/dv = B @ dP/dv`` would move with its value. Its lattice is made from ``hinge_range``
instead (:func:`ramp_knots`): knots evenly spaced, ``delta`` apart in the chordwise parameter,
across every place the hinge and its transition can be, ``delta`` the smallest transition width
over ``p + 1 + RAMP_INTERVALS``. On it, row ``i`` of section ``j`` of a flap turns by

    w_ij = S(clip((t_i - uh_j) / (ut_j - uh_j - (p + 1) delta), 0, 1)),   S(x) = x^3 (10 - 15 x + 6 x^2)

(slat: ``S(clip((uh_j - t_{i+p+1}) / (uh_j - ut_j - (p + 1) delta), 0, 1))``), ``t`` the chordwise knots,
``uh_j``, ``ut_j`` the chordwise parameters of the hinge line and of the end of the transition at
section ``j``. A row whose basis function reaches ahead of the hinge (``t_i <= uh_j``) does not turn,
so a point ahead of the hinge does not move; one whose function reaches behind the transition turns
fully (its support spans at most ``(p + 1) delta``), so a point there turns rigidly; between them a
smooth step over ``RAMP_INTERVALS delta`` (twice differentiable: a difference quotient across its
ends sees no corner). ``uh_j`` and ``ut_j`` are parameters of points that move along the local chord
linearly with the hinge fractions, so ``w`` is a smooth function of them with the exact derivative
:meth:`HingeRamp.weights` (through the lattice map's inverse Jacobian).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import product

import numpy as np

from ffdcli.box.box import Box
from ffdcli.box.refine import edges_at, span_fractions
from ffdcli.errors import InputError
from ffdcli.lattice.embedding import embed
from ffdcli.lattice.lattice import derivatives, evaluate

#: Knot intervals across a variable hinge's ramp beyond the ``p + 1`` of one basis function.
RAMP_INTERVALS = 2
#: Points along the hinge line at which the knots' extent is read.
RANGE_SAMPLES = 17


def line_params(box: Box, base, chords, href, sigma, ahead, hinge):
    """(uh, ut, duh, dut): (k,) the chordwise parameters of the hinge line for fractions ``hinge`` (E,)
    and of the end of its transition at positions ``sigma`` (k,) along it, (E, k) their derivatives
    by the hinge fractions (the arguments as the fields of :class:`HingeRamp`)."""
    h = np.asarray(hinge, dtype=float)
    ends = base + (h - href)[:, None] * chords
    k = len(sigma)
    if len(ends) == 1:
        X = np.repeat(ends, k, axis=0)
        dX = np.repeat(chords[:, None, :], k, axis=1)
    else:
        s = np.asarray(sigma)[:, None]
        X = (1.0 - s) * ends[0] + s * ends[1]
        dX = np.stack([(1.0 - s) * chords[0], s * chords[1]])
    lat = box.lattice()
    pts = box.core_points(np.concatenate([X, X + ahead]))
    e = embed(lat, pts)
    if not e.inside.all():
        raise InputError("a control surface's hinge or transition lies outside the box (is its hinge_range "
                         "right?)")
    # du/dx: the first row of the inverse of the map's Jacobian (gdim x pdim, square) at each point
    grad = np.linalg.inv(derivatives(lat, e.params))[:, 0, :]            # (2k, gdim)
    # one more Newton step on u (the embedding stops at its tolerance, 1e-10 of the lattice: a
    # difference quotient of u would see it), then u to rounding
    u = e.params[:, 0] + np.einsum("kd,kd->k", grad, pts - evaluate(lat, e.params))
    dXc = np.stack([box.core_points(d) for d in dX])                     # (E, k, gdim)
    duh = np.einsum("kd,ekd->ek", grad[:k], dXc)
    dut = np.einsum("kd,ekd->ek", grad[k:], dXc)
    return u[:k], u[k:], duh, dut


@dataclass(frozen=True, eq=False)
class HingeRamp:
    """The share of the angle of each row and section of a variable hinge's device.

    box
        The (refined) box whose baseline map the parameters are read in.
    base, chords
        (E, 3) the hinge points at the reference hinge ``href`` (E,) and the local chord vectors
        (leading to trailing edge) at the device's ends: end ``e``'s hinge point for fractions ``h``
        is ``base[e] + (h[e] - href[e]) chords[e]``.
    sigma
        (k,) where each section lies along the hinge line (0 inner end, 1 outer end; clipped).
    ahead
        (k, 3) from the hinge line to the end of the transition at each section (``sign *
        transition`` local chords).
    sign
        +1 flap, -1 slat.
    delta
        The knot spacing the ramp is made for (``(p + 1) delta`` is the widest support it allows).
    extent
        (2,) the parameters the hinge and its transition can reach over the range, one support
        further ((lowest, highest) for a flap; (highest, lowest) for a slat).
    """

    box: Box
    base: np.ndarray
    chords: np.ndarray
    href: np.ndarray
    sigma: np.ndarray
    ahead: np.ndarray
    sign: float
    delta: float
    extent: np.ndarray

    def weights(self, hinge) -> tuple[np.ndarray, np.ndarray]:
        """(n, k) the share of the angle of each row at each section for ``hinge`` (E,) and (E, n, k)
        its derivative by the hinge fractions (0 where the share is clipped)."""
        uh, ut, duh, dut = line_params(self.box, self.base, self.chords, self.href, self.sigma, self.ahead, hinge)
        t, p = np.asarray(self.box.knots[0]), self.box.degree[0]
        n = len(t) - p - 1
        c = (p + 1) * self.delta
        if self.sign > 0:
            D = ut - uh - c
            r = (t[:n, None] - uh) / D
            dr = (-duh[:, None, :] - r * (dut - duh)[:, None, :]) / D
        else:
            D = uh - ut - c
            r = (uh - t[p + 1:n + p + 1, None]) / D
            dr = (duh[:, None, :] - r * (duh - dut)[:, None, :]) / D
        x = np.clip(r, 0.0, 1.0)
        # the smooth step x^3 (10 - 15 x + 6 x^2): 0 and 1 with two derivatives at its ends, so that the
        # mesh is twice differentiable in the hinge (difference quotients see no corner)
        w = x * x * x * (10.0 + x * (-15.0 + 6.0 * x))
        return w, 30.0 * (x * (1.0 - x)) ** 2 * dr

    def reachable(self) -> np.ndarray:
        """(n,) bool: the rows some hinge of the range turns (behind (flap; slat: ahead of) the
        extent's near end)."""
        t, p = np.asarray(self.box.knots[0]), self.box.degree[0]
        n = len(t) - p - 1
        if self.sign > 0:
            return t[:n] > self.extent[0]
        return t[p + 1:n + p + 1] < self.extent[0]

    def knots(self) -> np.ndarray:
        """The chordwise knots the ramp needs: evenly spaced, less than :attr:`delta` apart, across
        :attr:`extent` (clipped to the box)."""
        a, b = sorted(self.extent)
        a, b = max(a, 0.0), min(b, 1.0)
        count = max(1, math.ceil((b - a) / (self.delta * (1.0 - 1e-9))))
        return a + (b - a) * np.arange(count + 1) / count


def make_ramp(box: Box, ends: np.ndarray, sign: float, transition: float, href, hinge_range,
              sigma: np.ndarray) -> HingeRamp:
    """The :class:`HingeRamp` of a device with ``ends`` (E, 3, 3) (leading-edge, trailing-edge and
    hinge point at each end, the hinge at ``href``) for sections at ``sigma`` (k,) along its hinge
    line; its spacing and extent from every corner of ``hinge_range`` (lo, hi) at every end."""
    le, te, H = ends[:, 0], ends[:, 1], ends[:, 2]
    chords = te - le
    href = np.asarray(href, dtype=float)
    if len(ends) == 1:
        ahead = np.repeat(sign * transition * chords, len(sigma), axis=0)
    else:
        s = np.asarray(sigma)[:, None]
        f = span_fractions(box, (1.0 - s) * H[0] + s * H[1])
        ahead = sign * transition * np.array([np.subtract(*edges_at(box, float(x))[::-1]) for x in f])
    # the extent and the spacing: over the corners of the range, read at RANGE_SAMPLES points along
    # the line (so that the refined box, with more sections, finds the same)
    line = np.linspace(0.0, 1.0, RANGE_SAMPLES) if len(ends) == 2 else np.zeros(1)
    if len(ends) == 2:
        g = span_fractions(box, (1.0 - line[:, None]) * H[0] + line[:, None] * H[1])
        line_ahead = sign * transition * np.array([np.subtract(*edges_at(box, float(x))[::-1]) for x in g])
    else:
        line_ahead = ahead[:1]
    uh, ut = [], []
    for corner in product(tuple(hinge_range), repeat=len(ends)):
        a, b, _, _ = line_params(box, H, chords, href, line, line_ahead, corner)
        uh.append(a)
        ut.append(b)
    uh, ut = np.concatenate(uh), np.concatenate(ut)
    width = float(np.min(sign * (ut - uh)))
    if not width > 0:
        raise InputError("the transition of a variable hinge leaves the box")
    p = box.degree[0]
    delta = width / (p + 1 + RAMP_INTERVALS)
    c = (p + 1) * delta
    extent = np.array([uh.min() - c, ut.max() + c]) if sign > 0 else np.array([uh.max() + c, ut.min() - c])
    return HingeRamp(box=box, base=H.copy(), chords=chords, href=href, sigma=np.asarray(sigma, dtype=float),
                     ahead=ahead, sign=sign, delta=delta, extent=extent)
