"""2D airfoil fitting: the ``shape`` values that morph the mesh airfoil into a target airfoil.

The deformed surface is ``X = X0 + B (P' - P0)`` and a ``shape`` change moves the upper (k = l-1)
and lower (k = 0) control points along the thickness axis only, so each surface point's thickness
coordinate is linear in the shape values ``a`` while its chordwise coordinate stays put:

    eta_s(a) = eta0_s + sum_v B[s, row(v)] a_v.

The target airfoil (Selig or Lednicer file) is placed on the mesh airfoil's chord line (same
leading and trailing edge), split at its leading edge into an upper and a lower branch, and
interpolated at each surface point's chordwise position on the point's own side. The fit solves
the Tikhonov-regularised linear least-squares problem

    min_a |A a - (eta_T - eta0)|^2 + lam |a|^2,   lam = 1e-8 * |A|_F^2 / n_vars,

whose small ``lam`` only pins down control points that the surface barely sees (it changes the
residual by far less than the mesh resolution). Deviations are reported in chord units, as the
thickness-wise distance between the deformed surface and the target at the same chordwise position.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError

REG = 1e-8


@dataclass
class FitProblem:
    """The linear model of one airfoil fit, in chord units."""

    A: np.ndarray          # (S, 2n) d eta / d (upper[0..n-1], lower[0..n-1])
    rhs: np.ndarray        # (S,) target minus original thickness coordinate
    chord: float
    n: int


def place_target(coords: np.ndarray, le: np.ndarray, te: np.ndarray, thickness_dir2: np.ndarray):
    """Put a unit-chord-ish airfoil (K, 2) on the chord line from ``le`` to ``te`` (2D points).

    Returns the target's (upper, lower) branches as (xi, eta) arrays in chord units with xi from
    0 (leading edge) to 1 (trailing edge), eta along the mesh thickness direction."""
    c = np.asarray(coords, dtype=np.float64)
    te_t = 0.5 * (c[0] + c[-1])
    i_le = int(np.argmax(np.hypot(*(c - te_t).T)))
    le_t = c[i_le]
    d_t = te_t - le_t
    L = np.hypot(*d_t)
    e1 = d_t / L
    e2 = np.array([-e1[1], e1[0]])
    xi = (c - le_t) @ e1 / L
    eta = (c - le_t) @ e2 / L
    upper = (xi[: i_le + 1][::-1], eta[: i_le + 1][::-1])
    lower = (xi[i_le:], eta[i_le:])
    if np.mean(upper[1]) < np.mean(lower[1]):      # a file running the other way round
        upper, lower = lower, upper
    return _monotone(*upper), _monotone(*lower)


def _monotone(xi: np.ndarray, eta: np.ndarray):
    o = np.argsort(xi, kind="stable")
    xi, eta = xi[o], eta[o]
    keep = np.r_[True, np.diff(xi) > 0]
    return xi[keep], eta[keep]


def build_problem(run, target: np.ndarray) -> FitProblem:
    """The linear least-squares model for the 2D design ``run`` (``ffdcli.pipeline.DesignRun``)."""
    box, emb, surf = run.box, run.prep.embedding, run.prep.surface
    if box.dim != 2:
        raise InputError("ffd fit works on 2D airfoil meshes; this design's mesh is 3D",
                         path=run.design.path)
    n, _, l = box.shape
    ca, ta = box.axes.chord, box.axes.thickness
    le = box.le_points[0][[ca, ta]]
    te = box.te_points[0][[ca, ta]]
    chord = float(np.hypot(*(te - le)))
    e1 = (te - le) / chord
    e2 = np.array([-e1[1], e1[0]])
    if e2[1] < 0:              # thickness direction must be "up" (+ mesh thickness axis)
        e2 = -e2
    X = surf.points[:, [ca, ta]]
    xi = (X - le) @ e1 / chord
    eta = (X - le) @ e2 / chord
    (xu, yu), (xl, yl) = place_target(target, le, te, e2)
    upper_side = eta >= 0
    eta_t = np.where(upper_side, np.interp(xi, xu, yu), np.interp(xi, xl, yl))
    # Columns: unit thickness move of control point (i, 0, k) -> surface thickness moves.
    A = np.zeros((len(X), 2 * n))
    t_dir = np.zeros(2)
    t_dir[1] = 1.0            # the core's 2D coordinates are (chord axis, thickness axis)
    for col, (i, k) in enumerate([(i, l - 1) for i in range(n)] + [(i, 0) for i in range(n)]):
        dP = np.zeros((n, l, 2))
        dP[i, k] = t_dir
        d = emb.displace(dP)                      # (S, 2) in (chord, thickness) mesh coordinates
        A[:, col] = (d @ e2) / chord
    return FitProblem(A=A, rhs=eta_t - eta, chord=chord, n=n)


def solve(problem: FitProblem, reg: float = REG):
    """Shape values (upper (n,), lower (n,)) in mesh units, and the residual before/after."""
    A, r = problem.A, problem.rhs
    lam = reg * float(np.sum(A * A)) / A.shape[1]
    M = A.T @ A + lam * np.eye(A.shape[1])
    a = np.linalg.solve(M, A.T @ r)
    after = A @ a - r
    stats = {"before": {"rms": float(np.sqrt(np.mean(r ** 2))), "max": float(np.abs(r).max())},
             "after": {"rms": float(np.sqrt(np.mean(after ** 2))), "max": float(np.abs(after).max())}}
    vals = a * problem.chord
    return vals[: problem.n], vals[problem.n:], stats


def fitted_design_data(design, upper, lower, out_path: Path) -> dict:
    """The design file's data with its shape change replaced by the fitted values (paths rebased)."""
    import copy

    data = copy.deepcopy(design.data)
    base = Path(out_path).resolve().parent
    data["mesh"] = os.path.relpath(Path(design.mesh).resolve(), base)
    shape = {"shape": {"upper": [float(v) for v in upper], "lower": [float(v) for v in lower],
                       "sections": "all"}}
    changes = [c for c in data.get("changes") or [] if "shape" not in c]
    data["changes"] = changes + [shape]
    output = data.get("output") or {}
    for key in ("mesh", "lattice", "plot"):
        if key in output and key in design.output and design.output[key] is not None:
            output[key] = os.path.relpath(Path(design.output[key]).resolve(), base)
    if output:
        data["output"] = output
    return data


def fit_design(config, target_file, out_yaml=None, *, overrides=(), progress=None, reg: float = REG) -> dict:
    """Fit the shape of 2D design ``config`` to ``target_file``; write ``out_yaml`` if given."""
    import yaml

    from ffdcli.atomic import atomic_write, check_writable
    from ffdcli.design import load_design
    from ffdcli.formats.airfoil import read_airfoil
    from ffdcli.pipeline import load_run

    design = load_design(config, overrides=overrides)
    other = [next(iter(c)) for c in design.changes_spec if "shape" not in c]
    if other:
        raise InputError(f"ffd fit fits shape values to the original airfoil; remove the other changes "
                         f"({', '.join(other)}) or fit a design that has only shape changes",
                         path=design.path, key="changes")
    design.changes_spec = []          # the fit replaces any shape change; its lengths need not match
    if out_yaml is not None:
        check_writable(out_yaml, inputs=(design.mesh, design.path))
    target = read_airfoil(target_file)
    run = load_run(design, progress=progress)
    problem = build_problem(run, target.coords)
    upper, lower, stats = solve(problem, reg)
    report = {"design": str(design.path), "target": str(target_file), "name": target.name,
              "lattice": list(run.box.lattice_shape), "chord": problem.chord,
              "points": int(len(problem.rhs)), **stats,
              "upper": upper.tolist(), "lower": lower.tolist()}
    if out_yaml is not None:
        data = fitted_design_data(design, upper, lower, Path(out_yaml))
        with atomic_write(out_yaml, "w") as fh:
            fh.write(f"# fitted by ffd fit to {Path(target_file).name} ({target.name}): max deviation "
                     f"{stats['before']['max']:.5f} -> {stats['after']['max']:.5f} chords\n")
            yaml.safe_dump(data, fh, sort_keys=False, default_flow_style=None)
        report["output"] = str(out_yaml)
    return report
