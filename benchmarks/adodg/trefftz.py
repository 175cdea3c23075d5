"""Induced drag from the flow behind the wing: the crossflow's kinetic energy in a Trefftz plane.

ADODG Case 3 asks for the span efficiency e = CL^2 / (pi AR CDi) with CDi the induced drag, "a
Trefftz-plane integral, or CD minus the mesh's zero-lift drag". The second (``e_drag``,
:mod:`benchmarks.adodg.case3_report`) carries whatever spurious drag the Euler solution has beyond its
zero-lift value; this module is the first, from an SU2 flow solution (its ``restart_flow.dat``).

A plane normal to the free stream, a distance ``d`` behind the root's trailing edge, is sampled on a
tensor grid (fine over the wake, growing geometrically to the plane's edges); the solution is
interpolated linearly in the tetrahedra of the points' Delaunay triangulation; the induced drag of the
half wing is the crossflow energy over the half plane ``y >= 0`` (the linearised compressible form of
the far-field drag, Kusunose's wake integral without the entropy terms)::

    Di = rho_inf / 2 * integral( v^2 + w^2 - (1 - M^2) u^2 ) dS,    CDi = Di / (q_inf S_ref)

with (u, v, w) the velocity less the free stream in wind axes (u along it). In an exact inviscid wake
the energy does not change with ``d``; on a mesh the wake's vortices diffuse and the energy falls as
the plane moves downstream, so the command prints CDi at several distances and the trend is part of
the answer. The oracle (tests): the flow of a flat plate moving normal to itself, which is the Trefftz
plane of the elliptic load, gives e = 1.

    python -m benchmarks.adodg.trefftz out/adodg3h/case3/evals/0001 --distances 0.25 0.5 1 2
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib
import numpy as np
from scipy.interpolate import LinearNDInterpolator
from scipy.spatial import Delaunay

from benchmarks.adodg import evaluate
from benchmarks.adodg.case3_report import config_alpha, history_file, last_history
from ffdcli.optimize.solvers.su2 import config_value, read_config

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)

SPAN = 3.0              # the half wing's span (chord 1)
AREA = 3.0              # its reference area
ASPECT = 6.0            # the full wing's aspect ratio


class TrefftzError(Exception):
    """A solution that cannot be read (the message names the file)."""


def read_restart(path: Path) -> dict[str, np.ndarray]:
    """The fields of an SU2 binary restart file (``restart_flow.dat``): {name: (n_points,) float64}
    (:func:`benchmarks.adodg.evaluate.read_restart` reads the layout)."""
    try:
        names, values = evaluate.read_restart(path)
    except ValueError as exc:
        raise TrefftzError(str(exc)) from None
    return {name: values[:, i] for i, name in enumerate(names)}


def wind_axes(alpha_deg: float) -> np.ndarray:
    """(3, 3) rows: the free stream's direction, the span (y), the lift direction, for an angle of
    attack in the x-z plane (SU2's 3-D convention: x chord, z lift)."""
    a = math.radians(alpha_deg)
    return np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])


def stretched(fine_end: float, h: float, far: float, growth: float = 1.15, start: float = 0.0) -> np.ndarray:
    """Nodes from ``start`` to ``far``: spacing ``h`` up to ``fine_end``, then growing by ``growth``."""
    n_fine = max(int(math.ceil((fine_end - start) / h)), 1)
    nodes = list(np.linspace(start, start + n_fine * h, n_fine + 1))
    step = h
    while nodes[-1] < far:
        step *= growth
        nodes.append(min(nodes[-1] + step, far))
    return np.array(nodes)


def plane_grid(h: float = 0.02, span_fine: float = 3.4, height_fine: float = 0.5, extent: float = 30.0,
               growth: float = 1.15) -> tuple[np.ndarray, np.ndarray]:
    """The plane's nodes: y (ny,) from the symmetry plane outward, z (nz,) across the wake; spacing ``h``
    over ``y <= span_fine`` and ``|z| <= height_fine``, growing to ``extent``."""
    y = stretched(span_fine, h, extent, growth)
    up = stretched(height_fine, h, extent, growth)
    return y, np.concatenate([-up[:0:-1], up])


def trapezoid_2d(y: np.ndarray, z: np.ndarray, f: np.ndarray) -> float:
    """The integral of ``f`` (ny, nz) over the tensor grid (trapezoidal rule in each direction)."""
    return float(np.trapezoid(np.trapezoid(f, z, axis=1), y))


def crossflow_integral(y: np.ndarray, z: np.ndarray, u: np.ndarray, v: np.ndarray, w: np.ndarray,
                       mach: float) -> tuple[float, float]:
    """(the crossflow term integral(v^2 + w^2) dS, the axial term integral((1 - M^2) u^2) dS) over the
    grid; u, v, w (ny, nz) the perturbation velocity in wind axes. NaN samples (outside the mesh) are
    taken as zero perturbation (the plane's far parts, beyond the far field)."""
    cross = np.nan_to_num(v * v + w * w)
    axial = np.nan_to_num((1.0 - mach * mach) * u * u)
    return trapezoid_2d(y, z, cross), trapezoid_2d(y, z, axial)


def circulation(y: np.ndarray, z: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(ny,) the circulation of the plane's streamwise vorticity outboard of each station y: the
    counter-clockwise line integral of (v, w) around the rectangle [y, y_max] x [z_min, z_max] (its
    inboard side, the outboard side and the top and bottom from y outward), positive for lift (+z) on
    the wing's right half. The whole contour is kept, so no vorticity is cut off by the plane's size;
    NaN samples count as zero perturbation."""
    v, w = np.nan_to_num(v), np.nan_to_num(w)
    inboard = -np.trapezoid(w, z, axis=1)
    outboard = np.trapezoid(w[-1], z)
    edges = v[:, 0] - v[:, -1]
    pieces = 0.5 * (edges[1:] + edges[:-1]) * np.diff(y)
    outward = np.concatenate([np.cumsum(pieces[::-1])[::-1], [0.0]])
    return inboard + outboard + outward


def _second_antiderivative_log(x: np.ndarray) -> np.ndarray:
    """F with F'' = ln|x| and F(0) = 0: x^2 ln|x| / 2 - 3 x^2 / 4."""
    ax = np.abs(x)
    out = np.zeros_like(x, dtype=float)
    m = ax > 0
    out[m] = 0.5 * x[m] ** 2 * np.log(ax[m]) - 0.75 * x[m] ** 2
    return out


def sheet_energy(y: np.ndarray, gamma: np.ndarray) -> float:
    """The crossflow energy per unit density of a flat vortex sheet with circulation ``gamma`` (n,) at
    stations ``y`` (n,) from the symmetry plane out (mirrored to y < 0; ``gamma`` taken as linear
    between stations and zero beyond the last), the full sheet: E = -1/(4 pi) sum_ij g_i g_j I_ij with
    g the sheet strength -dGamma/dy per interval and I_ij the exact double integral of ln|y1 - y2| over
    intervals i and j. Di of the full wing = rho * E."""
    ys = np.concatenate([-y[:0:-1], y])
    gs = np.concatenate([gamma[:0:-1], gamma])
    if gs[-1] != 0.0:                                   # close the sheet: Gamma falls to zero at its ends
        ys = np.concatenate([[ys[0] - (ys[1] - ys[0])], ys, [ys[-1] + (ys[-1] - ys[-2])]])
        gs = np.concatenate([[0.0], gs, [0.0]])
    a, b = ys[:-1], ys[1:]
    g = -np.diff(gs) / (b - a)
    F = _second_antiderivative_log
    ii = (F(b[:, None] - a[None, :]) - F(b[:, None] - b[None, :]) - F(a[:, None] - a[None, :])
          + F(a[:, None] - b[None, :]))
    return float(-(g @ ii @ g) / (4.0 * math.pi))


def sheet_efficiency(y: np.ndarray, gamma: np.ndarray) -> float:
    """e of the load ``gamma`` (n,) at stations ``y`` (the half span, symmetric wing): L^2 / (pi q b^2 Di)
    with L = rho U integral(Gamma) over the full span and Di = rho * :func:`sheet_energy`, b the wing's
    span 2 :data:`SPAN` (not the wake's, which spreads): e = (2 int Gamma dy)^2 / (pi / 2 * b^2 * E)."""
    lift = 2.0 * float(np.trapezoid(gamma, y))
    return lift * lift / (0.5 * math.pi * (2.0 * SPAN) ** 2 * sheet_energy(y, gamma))


@dataclass(frozen=True)
class PlaneDrag:
    """What one plane says: the distance behind the root's trailing edge; from the crossflow energy,
    CDi and its two terms (crossflow, axial, both divided by U^2 S); from the plane's circulation, the
    lift it carries (``cl_wake``, 2 int Gamma dy / (U S)) and the span efficiency of that load as a flat
    sheet (``e_wake``); the share of the plane's samples outside the mesh; the stations ``y`` (ny,) and
    the wake's load there, ``load`` (ny,) = c cl = 2 Gamma / U (Kutta-Joukowski)."""

    distance: float
    cdi: float
    crossflow: float
    axial: float
    cl_wake: float
    e_wake: float
    outside: float
    y: np.ndarray = field(default_factory=lambda: np.zeros(0))
    load: np.ndarray = field(default_factory=lambda: np.zeros(0))


class Solution:
    """An SU2 flow solution ready to be sampled: the points' Delaunay triangulation (built once) and the
    velocity, with the free stream and its axes.

    points : (n, 3); velocity : (n, 3); alpha : degrees; mach : the free-stream Mach number; u_inf : the
    free-stream speed (default: the median speed of the 1 % of points farthest from the origin)."""

    def __init__(self, points: np.ndarray, velocity: np.ndarray, alpha: float, mach: float,
                 u_inf: float | None = None):
        self.points = np.asarray(points, dtype=float)
        self.velocity = np.asarray(velocity, dtype=float)
        self.axes = wind_axes(alpha)
        self.mach = mach
        if u_inf is None:
            r = np.linalg.norm(self.points, axis=1)
            far = r >= np.quantile(r, 0.99)
            u_inf = float(np.median(np.linalg.norm(self.velocity[far], axis=1)))
        self.u_inf = u_inf
        self.interpolator = LinearNDInterpolator(Delaunay(self.points), self.velocity)

    def plane(self, distance: float, origin: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, ...]:
        """The perturbation velocity (u, v, w), each (ny, nz), in wind axes on the plane ``distance``
        behind ``origin`` along the free stream, at span ``y`` and wind-axis height ``z``."""
        yy, zz = np.meshgrid(y, z, indexing="ij")
        xyz = (np.asarray(origin, dtype=float) + distance * self.axes[0] + yy[..., None] * self.axes[1]
               + zz[..., None] * self.axes[2])
        vel = self.interpolator(xyz.reshape(-1, 3)).reshape(*yy.shape, 3) @ self.axes.T
        vel[..., 0] -= self.u_inf
        return vel[..., 0], vel[..., 1], vel[..., 2]

    def drag(self, distance: float, origin: np.ndarray, y: np.ndarray, z: np.ndarray,
             area: float = AREA) -> PlaneDrag:
        """:class:`PlaneDrag` of the plane ``distance`` behind ``origin`` (the half plane y >= 0)."""
        u, v, w = self.plane(distance, origin, y, z)
        cross, axial = crossflow_integral(y, z, u, v, w, self.mach)
        scale = self.u_inf ** 2 * area
        gamma = circulation(y, z, v, w)
        return PlaneDrag(distance=distance, cdi=(cross - axial) / scale, crossflow=cross / scale,
                         axial=axial / scale, cl_wake=2.0 * float(np.trapezoid(gamma, y)) / (self.u_inf * area),
                         e_wake=sheet_efficiency(y, gamma), outside=float(np.isnan(u).mean()), y=y,
                         load=2.0 * gamma / self.u_inf)


def span_efficiency(cl: float, cdi: float, aspect: float = ASPECT) -> float:
    """e = CL^2 / (pi AR CDi)."""
    return cl * cl / (math.pi * aspect * cdi)


def config_mach(folder: Path) -> float | None:
    """``MACH_NUMBER`` of the folder's flow configuration (``flow.cfg``, ``config_CFD.cfg`` or ``config_DSN.cfg``)."""
    for name in ("flow.cfg", "config_CFD.cfg", "config_DSN.cfg"):
        cfg = Path(folder) / name
        if cfg.is_file():
            value = config_value(read_config(cfg), "MACH_NUMBER")
            return None if value is None else float(value)
    return None


def analyse(folder: Path, distances: list[float], h: float = 0.01, extent: float = 30.0) -> dict:
    """CDi and e of a solved folder (``restart_flow.dat``, its config and flow history) at each distance
    behind the root's trailing edge (x = 1, z = 0)."""
    folder = Path(folder)
    path = folder / "restart_flow.dat"
    if not path.is_file():
        raise TrefftzError(f"{path}: no such file (a folder where SU2's flow wrote its restart)")
    fields = read_restart(path)
    alpha, mach = config_alpha(folder), config_mach(folder)
    if alpha is None or mach is None:
        raise TrefftzError(f"{folder}: no AOA or MACH_NUMBER in its flow configuration")
    if not history_file(folder).is_file():
        raise TrefftzError(f"{history_file(folder)}: no such file (the flow's history, for its CL and CD)")
    hist = last_history(history_file(folder))
    cl = hist.get("CL", hist.get("LIFT"))
    sol = Solution(np.column_stack([fields["x"], fields["y"], fields["z"]]),
                   np.column_stack([fields["Velocity_x"], fields["Velocity_y"], fields["Velocity_z"]]), alpha, mach)
    y, z = plane_grid(h=h, extent=extent)
    rows = [sol.drag(d, np.array([1.0, 0.0, 0.0]), y, z) for d in distances]
    return {"folder": str(folder), "CL": cl, "CD": hist.get("CD", hist.get("DRAG")), "alpha": alpha, "mach": mach,
            "u_inf": sol.u_inf, "planes": [{"distance": r.distance, "CDi": r.cdi, "crossflow": r.crossflow,
                                            "axial": r.axial, "outside": r.outside, "e": span_efficiency(cl, r.cdi),
                                            "CL_wake": r.cl_wake, "e_wake": r.e_wake, "y": r.y, "load": r.load}
                                           for r in rows]}


def plot(reports: list[dict], labels: list[str], path: Path) -> None:
    """The wake's load c cl(y) of each report at its first plane, each beside the ellipse of its lift."""
    fig, ax = plt.subplots(figsize=(8, 4.8))
    ys = np.linspace(0.0, SPAN, 200)
    for rep, label, color in zip(reports, labels, ("C0", "C3", "C2", "C1"), strict=False):
        p = rep["planes"][0]
        keep = p["y"] <= 1.2 * SPAN
        ax.plot(p["y"][keep], p["load"][keep], color=color,
                label=f"{label}: CL from the wake {p['CL_wake']:.4f}, e {p['e_wake']:.4f}")
        c0 = 4.0 * p["CL_wake"] * AREA / (math.pi * SPAN)
        ax.plot(ys, c0 * np.sqrt(1.0 - (ys / SPAN) ** 2), "--", color=color, lw=0.9, label=f"{label}: its ellipse")
    d = reports[0]["planes"][0]["distance"]
    ax.set_xlabel("span station y (chords; the tip at 3)")
    ax.set_ylabel("c cl = 2 Gamma / U")
    ax.set_title(f"The load the wake carries, {d:g} chord behind the trailing edge (Trefftz plane)")
    ax.set_xlim(0, 1.2 * SPAN)
    ax.set_ylim(bottom=-0.02)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.trefftz", description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path, nargs="+", help="a folder with SU2's restart_flow.dat, flow config, history")
    ap.add_argument("--distances", type=float, nargs="+", default=[0.02, 0.05, 0.1, 0.25, 1.0],
                    help="planes behind the root's trailing edge, chords (default 0.02 0.05 0.1 0.25 1)")
    ap.add_argument("--h", type=float, default=0.01, help="the plane's spacing over the wake, chords")
    ap.add_argument("--extent", type=float, default=30.0, help="the plane's half size, chords")
    ap.add_argument("--plot", type=Path, help="draw each folder's wake load at the first distance here (PNG)")
    ap.add_argument("--label", action="append", default=[], help="a folder's name in the picture (repeat)")
    args = ap.parse_args(argv)
    reports = []
    for folder in args.folder:
        try:
            rep = analyse(folder, args.distances, h=args.h, extent=args.extent)
        except TrefftzError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        reports.append(rep)
        print(f"{folder}: CL {rep['CL']:.6f}  CD {rep['CD']:.7f}  alpha {rep['alpha']:g}  U_inf {rep['u_inf']:.6f}")
        for p in rep["planes"]:
            print(f"  plane {p['distance']:5.2f} chords behind: energy CDi {p['CDi']:.7f} "
                  f"(crossflow {p['crossflow']:.7f}, axial {p['axial']:.2e}) e {p['e']:.4f}"
                  f" | circulation CL {p['CL_wake']:.5f} e {p['e_wake']:.4f}"
                  f" | outside the mesh {100 * p['outside']:.1f} %")
    if args.plot:
        labels = args.label + [Path(f).name for f in args.folder[len(args.label):]]
        plot(reports, labels, args.plot)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
