"""Inverse design with scipy.optimize and ffd's Python API: find the section twists of a target wing.

    python examples/scipy_inverse_twist.py [DESIGN.yaml]

The target is the design's own surface at a twist we pretend not to know; from zero twist, L-BFGS-B
with ffd's exact gradient (``surface_vjp``: dJ/dv from dJ/dX, no Jacobian formed) recovers it. For a
real optimisation replace J and dJ/dX by your solver's objective and adjoint surface sensitivity.
"""

import sys
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from ffdcli.api import DesignModel

design = sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parents[1] / "configs" / "rect_twist_sections.yaml"
model = DesignModel.from_file(design)                 # box and embedding: built once (cached)
secret = np.linspace(0.0, 6.0, model.n_vars)           # degrees, root to tip
model.set_values(secret)
target = model.surface_points().copy()


def objective(v):
    model.set_values(v)
    r = model.surface_points() - target               # J = |X(v) - X_target|^2 / 2, dJ/dX = r
    return 0.5 * float(np.sum(r * r)), model.surface_vjp(r)


res = minimize(objective, np.zeros(model.n_vars), jac=True, method="L-BFGS-B",
               bounds=list(zip(model.lower, model.upper)), options={"gtol": 1e-12, "ftol": 1e-15})
print(f"{res.nit} iterations, J = {res.fun:.3e}; variables {', '.join(model.names)}")
print(f"found  {np.round(res.x, 4).tolist()}\nsecret {secret.round(4).tolist()}")
print(f"max twist error {np.abs(res.x - secret).max():.2e} degrees")
