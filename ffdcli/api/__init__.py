"""The Python API for optimisation loops: load a design once, then set values and get products.

>>> from ffdcli.api import DesignModel
>>> model = DesignModel.from_file("configs/rect_twist_linear.yaml")
>>> model.set_values(model.values + 0.1)
>>> dJdv = model.mesh_vjp(dJdX_all_nodes)      # exact, through the volume-mesh motion

:mod:`ffdcli.api.model` (``DesignModel.evaluate(values)`` -> ``DesignPoint``: every product of the
derivative chain, :mod:`ffdcli.chain`, at those values), :mod:`ffdcli.api.pointsets`,
:mod:`ffdcli.api.constraints`, :mod:`ffdcli.api.gradient` (a sensitivity file to dJ/dv).
"""

from ffdcli.api.gradient import Gradient, gradient_from_file, read_sensitivity_for
from ffdcli.api.model import DesignModel, DesignPoint, constraints_report

__all__ = ["DesignModel", "DesignPoint", "Gradient", "constraints_report", "gradient_from_file",
           "read_sensitivity_for"]
