"""The protocol of the derivative chain's stages (OpenMDAO's ``compute`` / ``compute_jacvec_product``).

A stage is a map ``y = f(x)`` with its two products, and its input arrives on every call (no value is
set on the stage and read back later):

``forward(x) -> y``
    the map;
``jvp(x, dx) -> dy``
    ``J(x) dx``, the forward product;
``vjp(x, gy) -> gx``
    ``J(x)^T gy``, the reverse product (its exact transpose: ``<J dx, gy> = <dx, J^T gy>``).

What ``x`` and ``y`` are is the stage's own (an array, a tuple of arrays); a stage keeps only what
depends on its fixed data (the baseline lattice, the mesh) and, per product, the last result with the
hash of the input it came from (:mod:`ffdcli.chain.cache`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod


class Stage(ABC):
    """One link of the chain: :meth:`forward`, :meth:`jvp`, :meth:`vjp` (module docstring)."""

    @abstractmethod
    def forward(self, x):
        """``y = f(x)``."""

    @abstractmethod
    def jvp(self, x, dx):
        """``dy = J(x) dx``."""

    @abstractmethod
    def vjp(self, x, gy):
        """``gx = J(x)^T gy``."""
