"""Smallest planform area at fixed volume, with OpenMDAO: the volume constraint is active at the optimum.

A rectangular NACA 0012 wing (a generated surface mesh) may change its span factor ``s`` and its
chord factors at the root and the tip (``chord: {root, tip}``, both bounded by ``C = 1.2`` in the
design file's ``bounds:``). The planform area is measured on the moved wing: a point set of the
leading- and trailing-edge points at 21 span stations (trapezoidal rule). The enclosed volume must
stay at least that of the baseline (``volume: {lower: 1}``).

The analytic answer: the chord scales the thickness too, so with chord factor ``c(eta)`` the
volume is ``V = s * mean(c^2) * V0`` and the area ``A = s * mean(c) * A0``. At ``V = V0``,
``A / A0 = mean(c) / mean(c^2) >= 1 / C`` (as ``c <= C``), with equality only for ``c = C``
everywhere: both chord factors at their bound, ``s = 1 / C^2`` and ``A = A0 / C``, the volume
constraint active.

Run:  python examples/min_area_fixed_volume.py   (needs ``pip install 'ffdcli[openmdao]'``)
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

C_MAX = 1.2
STATIONS = 21


def write_case(folder: Path) -> Path:
    """A small surface wing and its design file in ``folder``."""
    from ffdcli.io.formats import write_mesh
    from ffdcli.testing.wings import rect_wing_planform, surface_mesh

    write_mesh(surface_mesh(rect_wing_planform(semi_span=3.0), n_chord=25, n_span=11), folder / "wing.su2")
    design = {
        "mesh": "wing.su2", "surface": "wing", "box": {"points": [4, 4, 2]},
        "changes": [{"span": 1.0}, {"chord": {"root": 1.0, "tip": 1.0}}],
        "bounds": {"c0.span": [0.3, 2.0], "c1.chord": [0.5, C_MAX]},
        "constraints": [{"volume": {"lower": 1.0}}],
    }
    path = folder / "min_area.yaml"
    path.write_text(yaml.safe_dump(design, sort_keys=False))
    return path


class PlanformArea:
    """Trapezoidal planform area from leading/trailing-edge points (K, 3) at increasing span stations."""

    def __init__(self, span_axis: int, K: int):
        self.span_axis, self.K = span_axis, K

    def component(self):
        import openmdao.api as om

        outer = self

        class Area(om.ExplicitComponent):
            def setup(self):
                self.add_input("edges", shape=(2 * outer.K, 3))
                self.add_output("area")
                self.declare_partials("area", "edges")

            def compute(self, inputs, outputs):
                outputs["area"] = outer.area(inputs["edges"])[0]

            def compute_partials(self, inputs, partials):
                partials["area", "edges"] = outer.area(inputs["edges"])[1].reshape(1, -1)

        return Area()

    def area(self, E):
        """(area, d area / d E (2K, 3)): sum of 0.5 (c_i + c_i+1) |s_i+1 - s_i|, c = |LE - TE|."""
        K, ax = self.K, self.span_axis
        le, te = E[:K], E[K:]
        d = le - te
        c = np.linalg.norm(d, axis=1)
        s = 0.5 * (le[:, ax] + te[:, ax])
        ds = np.diff(s)
        w = np.abs(ds)
        area = float(0.5 * np.sum((c[:-1] + c[1:]) * w))
        dc = np.zeros(K)
        dc[:-1] += 0.5 * w
        dc[1:] += 0.5 * w
        G = np.zeros((2 * K, 3))
        G[:K] += dc[:, None] * d / c[:, None]
        G[K:] -= dc[:, None] * d / c[:, None]
        dw = 0.5 * (c[:-1] + c[1:]) * np.sign(ds)            # d area / d s_i+1 (and minus for s_i)
        gs = np.zeros(K)
        gs[1:] += dw
        gs[:-1] -= dw
        G[:K, ax] += 0.5 * gs
        G[K:, ax] += 0.5 * gs
        return area, G


def run(folder: Path | None = None, maxiter: int = 60, disp: bool = False) -> dict:
    """Solve; returns the optimum, the analytic answer and the driver's record."""
    import openmdao.api as om

    from ffdcli.api import DesignModel
    from ffdcli.constraints import chord_lines
    from ffdcli.openmdao import FFDComponent

    tmp = tempfile.TemporaryDirectory() if folder is None else None
    folder = Path(tmp.name) if tmp else Path(folder)
    try:
        design = write_case(folder)
        base = DesignModel.from_file(design)
        le, te = chord_lines(base.run.box, np.linspace(0.0, 1.0, STATIONS))
        edges = np.vstack([le, te])
        area = PlanformArea(base.run.box.axes.span, STATIONS)
        A0 = area.area(edges)[0]

        prob = om.Problem(reports=False)
        prob.model.add_subsystem("ffd", FFDComponent(design=str(design), points={"edges": edges},
                                                     design_vars=True), promotes=["*"])
        prob.model.add_subsystem("planform", area.component(), promotes_inputs=["edges"])
        prob.model.add_subsystem("ratio", om.ExecComp(f"a = area / {A0!r}"), promotes_outputs=["a"])
        prob.model.connect("planform.area", "ratio.area")
        prob.model.add_objective("a")
        prob.model.add_constraint("k0_volume", lower=1.0)
        prob.driver = om.ScipyOptimizeDriver(optimizer="SLSQP", maxiter=maxiter, tol=1e-12, disp=disp)
        prob.setup()
        prob.run_driver()
        return {"span": float(prob["c0_span"][0]), "chord": np.asarray(prob["c1_chord"]).copy(),
                "area": float(prob["a"][0]), "volume": float(prob["k0_volume"][0]),
                "expected": {"span": 1.0 / C_MAX ** 2, "chord": C_MAX, "area": 1.0 / C_MAX},
                "iterations": prob.driver.iter_count, "success": prob.driver.result.success}
    finally:
        if tmp:
            tmp.cleanup()


def main() -> int:
    out = run(disp=True)
    exp = out["expected"]
    print(f"span factor {out['span']:.9f} (analytic {exp['span']:.9f})")
    print(f"chord factors {out['chord']} (analytic {exp['chord']})")
    print(f"area ratio {out['area']:.9f} (analytic {exp['area']:.9f}); volume ratio {out['volume']:.9f} (active: 1)")
    ok = abs(out["span"] - exp["span"]) < 1e-6 and abs(out["area"] - exp["area"]) < 1e-6
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
