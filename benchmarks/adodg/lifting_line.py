"""Prandtl's lifting line for ADODG Case 3: how close can twist at the box's control sections bring a
rectangular wing to the elliptic load? (The parameterization's own limit, without a mesh.)

Glauert's monoplane equation for a symmetric wing of span ``b = 2 s``, chord ``c(y)``, section lift slope
``a`` and incidence ``alpha(y)`` (radians): with ``y = -s cos(theta)`` and the circulation
``Gamma = 2 b V sum_n A_n sin(n theta)`` (odd ``n``),

    alpha(theta) = sum_n A_n sin(n theta) (4 b / (a c) + n / sin(theta)),

``CL = pi AR A_1`` and ``CDi = pi AR sum_n n A_n^2``, so ``e = A_1^2 / sum_n n A_n^2`` (Anderson,
*Fundamentals of Aerodynamics*, sec. 5.3; Glauert, *The Elements of Aerofoil and Airscrew Theory*). The
twist of the box's control sections reaches the wing through the box's spanwise B-spline (cubic, clamped,
uniform knots: ``ffd box``'s lattice): a section at ``y`` turns by ``sum_j N_j(y) t_j`` for small angles.
:func:`best_twist` minimises ``CDi`` at a given ``CL`` over the angle of attack and the twists with the
root's fixed, a quadratic programme with one linear equality, solved exactly (its KKT system).

    python -m benchmarks.adodg.lifting_line            # Case 3's wing: untwisted, and the best twist
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import BSpline


@dataclass(frozen=True)
class LiftingLine:
    """The collocation of Glauert's equation: ``M @ A = alpha`` at the stations ``y`` (both (N,)),
    odd modes ``n`` (N,), aspect ratio ``aspect_ratio``."""

    y: np.ndarray
    n: np.ndarray
    M: np.ndarray
    aspect_ratio: float


def lifting_line(semispan: float, chord: float, lift_slope: float, n_modes: int = 40) -> LiftingLine:
    """A rectangular wing's collocation: ``n_modes`` odd sine modes, stations ``theta = k pi / (2 N)``,
    k = 1..N (root at theta = pi/2, tip excluded)."""
    theta = np.arange(1, n_modes + 1) * math.pi / (2 * n_modes)
    n = 2 * np.arange(n_modes) + 1
    b = 2.0 * semispan
    s = np.sin(np.outer(theta, n))
    M = s * (4.0 * b / (lift_slope * chord) + n[None, :] / np.sin(theta)[:, None])
    return LiftingLine(y=semispan * np.cos(theta), n=n, M=M, aspect_ratio=b / chord)


def coefficients(ll: LiftingLine, alpha: np.ndarray) -> np.ndarray:
    """(N,) the modes' amplitudes A_n of the incidence ``alpha`` (N,) at the stations (radians)."""
    return np.linalg.solve(ll.M, alpha)


def efficiency(ll: LiftingLine, A: np.ndarray) -> float:
    """Span efficiency ``A_1^2 / sum n A_n^2``."""
    return float(A[0] ** 2 / np.sum(ll.n * A ** 2))


def twist_basis(y: np.ndarray, span_of_box: float, n_sections: int, degree: int = 3) -> np.ndarray:
    """(len(y), n_sections) the clamped uniform B-spline basis of the box's control sections at ``y``
    (degree ``min(degree, n_sections - 1)``)."""
    degree = min(degree, n_sections - 1)
    inner = np.linspace(0.0, span_of_box, n_sections - degree + 1)
    knots = np.concatenate([[0.0] * degree, inner, [span_of_box] * degree])
    return BSpline.design_matrix(np.clip(y, 0.0, span_of_box), knots, degree).toarray()


def best_twist(ll: LiftingLine, basis: np.ndarray, cl: float) -> tuple[float, np.ndarray, np.ndarray]:
    """The least induced drag at lift ``cl``: incidence ``alpha0 + basis @ t`` with ``t[0] = 0`` (the root's
    twist fixed; alpha0 free). Returns (alpha0, t (S,), A (N,)), radians."""
    G = np.linalg.inv(ll.M)
    X = np.column_stack([np.ones(len(ll.y)), basis[:, 1:]])          # unknowns: alpha0, t_1..t_{S-1}
    L = G @ X                                                          # A = L @ x
    H = 2.0 * L.T @ (ll.n[:, None] * L)                                # sum n A_n^2 = x' (H / 2) x
    c = L[0]                                                           # A_1 = c @ x
    kkt = np.block([[H, c[:, None]], [c[None, :], np.zeros((1, 1))]])
    rhs = np.concatenate([np.zeros(len(c)), [cl / (math.pi * ll.aspect_ratio)]])
    x = np.linalg.solve(kkt, rhs)[: len(c)]
    return float(x[0]), np.concatenate([[0.0], x[1:]]), L @ x


def case3(n_sections: int = 9, box_span: float = 3.0584780381722716, mach: float = 0.5, cl: float = 0.375,
          n_modes: int = 40) -> dict:
    """Case 3's wing (chord 1, semispan 3; the box to ``box_span``, H0's): the untwisted wing's e and the
    best twist's e, its angle of attack and twists (degrees, relative to the root)."""
    slope = 2.0 * math.pi / math.sqrt(1.0 - mach ** 2)                 # Prandtl-Glauert
    ll = lifting_line(3.0, 1.0, slope, n_modes)
    flat = coefficients(ll, np.ones(len(ll.y)))
    a0, t, A = best_twist(ll, twist_basis(ll.y, box_span, n_sections), cl)
    return {"e_untwisted": efficiency(ll, flat), "e_best": efficiency(ll, A), "alpha_deg": math.degrees(a0),
            "twist_deg": np.degrees(t).tolist(), "CL": float(math.pi * ll.aspect_ratio * A[0]),
            "sections": n_sections, "lift_slope": slope}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.lifting_line", description=__doc__.split("\n")[0])
    ap.add_argument("--sections", type=int, nargs="+", default=[9], help="control sections of the box, root first")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    out = [case3(k) for k in a.sections]
    if a.json:
        print(json.dumps(out))
        return 0
    for r in out:
        print(f"{r['sections']} sections: e untwisted {r['e_untwisted']:.4f}, best twist e {r['e_best']:.5f} at "
              f"alpha {r['alpha_deg']:.3f} deg; twist " + " ".join(f"{v:+.3f}" for v in r["twist_deg"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
