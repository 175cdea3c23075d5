"""The B-spline lattice: 1D splines, the tensor-product lattice, the Newton embedding of points, point
sets, size limits.
"""

from ffdcli.lattice.lattice import (  # the face: the names `ffdcli.lattice` offered before the packages
    Lattice,
    derivatives,
    derivatives_reference,
    eval_point_fixed_nb,
    eval_point_nb,
    evaluate,
    evaluate_reference,
    fixed_widths,
    kernel_args,
    padded_rows,
    size,
)

__all__ = [
    "Lattice",
    "derivatives",
    "derivatives_reference",
    "eval_point_fixed_nb",
    "eval_point_nb",
    "evaluate",
    "evaluate_reference",
    "fixed_widths",
    "kernel_args",
    "padded_rows",
    "size",
]
