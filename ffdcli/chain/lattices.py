"""values -> lattices: the design's changes on every component's lattice, and dP'/dv.

``x`` the design values (n_vars,) in the order of
:func:`ffdcli.parameterization.components.design_variables`; ``y`` a tuple of every component's
deformed control points ``(n, m, l, 3)`` (file order). The forward product is ``dP' = D dv``, the
reverse ``gv = D^T gP``, with ``D = dP'/dv`` of each component (its own columns of the variables).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ffdcli.chain.cache import Memo, digest
from ffdcli.chain.stage import Stage
from ffdcli.errors import InputError
from ffdcli.parameterization.changes import apply_changes
from ffdcli.parameterization.components import set_design_variables


class LatticeStage(Stage):
    """values -> lattices (module docstring).

    Parameters
    ----------
    components : sequence of ffdcli.parameterization.components.Component
        The prepared components (their changes' values are replaced by ``x`` on every call).
    error : callable (message, key) -> InputError, optional
        Names a change the lattice refuses by the design file's key (``Design.error``).
    """

    def __init__(self, components, error: Callable[[str, str], InputError] | None = None):
        self.components = tuple(components)
        self.error = error
        sizes = [sum(ch.size for ch in c.changes) for c in self.components]
        self.var_offsets = tuple(int(x) for x in np.cumsum([0] + sizes))
        self._valued = Memo()
        self._lattices = Memo()
        self._jacobians = Memo()

    @property
    def n_vars(self) -> int:
        return self.var_offsets[-1]

    def valued(self, x) -> list:
        """The components with their changes at values ``x``."""
        x = np.asarray(x, dtype=float)
        return self._valued.get(digest(x), lambda: set_design_variables(list(self.components), x))

    def forward(self, x) -> tuple[np.ndarray, ...]:
        x = np.asarray(x, dtype=float)
        return self._lattices.get(digest(x), lambda: tuple(self._lattice(c) for c in self.valued(x)))

    def _lattice(self, comp) -> np.ndarray:
        P = comp.P0
        for index, (change, spec) in enumerate(zip(comp.changes, comp.spec.changes_spec, strict=True)):
            try:
                P = apply_changes(P, comp.box.frame, [change])
            except InputError as e:      # a change refused on this lattice: name the design file and key
                if e.path is not None or self.error is None:
                    raise
                raise self.error(e.message, comp.spec.subkey(f"changes[{index}].{next(iter(spec))}")) from None
        return comp.freeze(P)

    def jacobians(self, x) -> tuple[np.ndarray, ...]:
        """Each component's dP'/dv (n_ctrl_c * 3, n_vars_c) at ``x``."""
        x = np.asarray(x, dtype=float)
        return self._jacobians.get(digest(x), lambda: tuple(c.lattice_jacobian() for c in self.valued(x)))

    def jacobian(self, x) -> np.ndarray:
        """dP'/dv (n_ctrl * 3, n_vars): block diagonal over the components (their lattices' rows one after
        the other, their variables' columns)."""
        blocks = self.jacobians(x)
        if len(blocks) == 1:
            return blocks[0]
        rows = np.cumsum([0] + [b.shape[0] for b in blocks])
        J = np.zeros((rows[-1], self.n_vars))
        for blk, r0, v0 in zip(blocks, rows, self.var_offsets, strict=False):
            J[r0:r0 + blk.shape[0], v0:v0 + blk.shape[1]] = blk
        return J

    def jvp(self, x, dx) -> tuple[np.ndarray, ...]:
        dx = np.asarray(dx, dtype=float)
        o = self.var_offsets
        return tuple((D @ dx[o[c]:o[c + 1]]).reshape(comp.P0.shape)
                     for c, (comp, D) in enumerate(zip(self.components, self.jacobians(x), strict=True)))

    def vjp(self, x, gy) -> np.ndarray:
        parts = [np.asarray(g, dtype=float).reshape(-1) @ D for g, D in zip(gy, self.jacobians(x), strict=True)]
        return np.concatenate(parts) if parts else np.zeros(0)
