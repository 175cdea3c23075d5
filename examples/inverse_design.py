"""Inverse design with OpenMDAO: recover a target wing from its surface points.

A rectangular NACA 0012 wing (a generated surface mesh) is deformed by a design with tip twist,
span, tip chord and upper/lower shape moves. The target is the same design at other values; SLSQP
starts from the undeformed wing and minimises the mean squared distance to the target surface,
subject to thickness >= 1 at a chord x span grid and volume >= 1 (both ratios to the baseline:
the target is thicker, so they hold there and bound the path). Exact derivatives come from
``FFDComponent.compute_jacvec_product``.

Run:  python examples/inverse_design.py   (needs ``pip install 'ffdcli[openmdao]'``)
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

TARGET = {"c0.twist.tip": 3.0, "c1.span": 1.06, "c2.chord.tip": 1.05}
SHAPE_UP = [0.0, 0.004, 0.006, 0.004, 0.002, 0.0]
SHAPE_LO = [0.0, -0.003, -0.004, -0.002, -0.001, 0.0]


def write_case(folder: Path) -> Path:
    """A small surface wing and its design file (all values at the baseline) in ``folder``."""
    from ffdcli.io.formats import write_mesh
    from ffdcli.testing.wings import rect_wing_planform, surface_mesh

    write_mesh(surface_mesh(rect_wing_planform(semi_span=3.0), n_chord=25, n_span=11), folder / "wing.su2")
    design = {
        "mesh": "wing.su2", "surface": "wing", "box": {"points": [6, 4, 2]},
        "changes": [{"twist": {"tip": 0.0}}, {"span": 1.0}, {"chord": {"tip": 1.0}},
                    {"shape": {"upper": [0.0] * 6, "lower": [0.0] * 6}}],
        "constraints": [{"thickness": {"chord": [0.2, 0.4, 0.6, 0.8], "span": [0.1, 0.5, 0.9], "lower": 1.0}},
                        {"volume": {"lower": 1.0}}],
    }
    path = folder / "inverse.yaml"
    path.write_text(yaml.safe_dump(design, sort_keys=False))
    return path


def target_values(model) -> np.ndarray:
    v = model.values.copy()
    for name, x in TARGET.items():
        v[model.names.index(name)] = x
    for i in range(6):
        v[model.names.index(f"c3.shape.upper[{i}]")] = SHAPE_UP[i]
        v[model.names.index(f"c3.shape.lower[{i}]")] = SHAPE_LO[i]
    return v


def run(folder: Path | None = None, maxiter: int = 60, disp: bool = False) -> dict:
    """Solve the inverse problem; returns the values found, the target values and the driver's record."""
    import openmdao.api as om

    from ffdcli.api import DesignModel
    from ffdcli.openmdao import FFDComponent

    tmp = tempfile.TemporaryDirectory() if folder is None else None
    folder = Path(tmp.name) if tmp else Path(folder)
    try:
        design = write_case(folder)
        ref = DesignModel.from_file(design)
        # Jacobi scaling (at the start): each variable scaled by the size of its column of dX/dv, so
        # that the misfit's Hessian seen by SLSQP has a unit diagonal (shape moves in mesh units and
        # angles in degrees differ by orders of magnitude in their effect on the surface).
        col = np.array([np.linalg.norm(ref.surface_jvp(e)) for e in np.eye(ref.n_vars)])
        v_target = target_values(ref)
        ref.set_values(v_target)
        X_target = ref.surface_points()
        S = len(X_target)

        prob = om.Problem(reports=False)
        ffd = prob.model.add_subsystem("ffd", FFDComponent(design=str(design)), promotes=["*"])
        misfit = om.ExecComp("f = sum((surface - target)**2) / n", surface={"shape": (S, 3)},
                             target={"shape": (S, 3), "val": X_target}, n={"val": float(S)},
                             has_diag_partials=False)
        prob.model.add_subsystem("misfit", misfit, promotes_inputs=["surface"])
        prob.driver = om.ScipyOptimizeDriver(optimizer="SLSQP", maxiter=maxiter, tol=1e-16, disp=disp)
        prob.setup()
        scale = col * np.sqrt(2.0 / S)
        for name in ffd.input_names:
            lo, hi = ffd.design_var_bounds(name)
            idx = [ref.names.index(n) for n in ffd.input_variables(name)]
            prob.model.add_design_var(name, lower=lo, upper=hi, scaler=scale[idx])
        prob.model.add_objective("misfit.f")
        prob.model.add_constraint("k0_thickness", lower=1.0)
        prob.model.add_constraint("k1_volume", lower=1.0)
        prob.setup()
        prob.run_driver()
        model = ffd.model
        return {"values": ffd.design_values(prob), "target": v_target, "names": list(model.names),
                "iterations": prob.driver.iter_count, "success": prob.driver.result.success,
                "thickness": np.asarray(prob["k0_thickness"]).copy(), "volume": float(prob["k1_volume"][0]),
                "misfit": float(prob["misfit.f"][0])}
    finally:
        if tmp:
            tmp.cleanup()


def main() -> int:
    out = run(disp=True)
    err = np.abs(out["values"] - out["target"])
    for name, v, t in zip(out["names"], out["values"], out["target"]):
        print(f"{name:22s} found {v: .9f}  target {t: .9f}")
    print(f"max |error| {err.max():.2e} after {out['iterations']} iterations; "
          f"volume {out['volume']:.6f}, thickness >= {out['thickness'].min():.6f}")
    return 0 if err.max() < 1e-6 else 1


if __name__ == "__main__":
    sys.exit(main())
