"""The gate's report: the counts of :func:`ffdcli.quality.gate.check_quality` (and of the
polyhedral gate, :mod:`ffdcli.quality.polyhedral`) and their words, the same for ``ffd deform`` and
``ffd check`` (see :mod:`ffdcli.quality.gate` for the rules)."""

from __future__ import annotations

from dataclasses import dataclass, field

from ffdcli.quality.rules import (
    DEFAULT_COLLAPSE,
    DEFAULT_ORTHO_LOSS,
    DEFAULT_ORTHO_MIN,
    DESIGN_SLACK,
    DESIGN_SLACK_DEG,
)


@dataclass(frozen=True)
class QualityReport:
    """The counts of :func:`check_quality` (see the module docstring for each rule).

    count, n_nodes
        Cells checked; nodes with an orthogonality (nodes of some cell).
    n_inverted, n_below
        The mesh as written (after): cells with q <= 0, and with 0 < q < ``threshold``.
    n_inverted_before, n_below_before
        The same of the input mesh (None without a mesh before).
    n_input_bad
        Cells already inverted or degenerate in the input (0 without a mesh before).
    n_new_inverted, n_worse, n_ortho_failed
        What the gate refuses on: cells the design inverted, cells made markedly worse, nodes that
        lost orthogonality (0 without a mesh before).
    min_before, min_after
        Smallest q (None when unknown / no cells).
    ortho_before, ortho_after, ortho_loss
        Smallest node orthogonality (degrees) before / after, and the largest loss of one node.
    n_ortho_low, n_ortho_low_before
        Nodes below ``ortho_min`` after / before.
    n_design_cells, n_design_nodes
        Cells and nodes that the rules above would fail but that the design's own FFD map shapes
        so (within ``DESIGN_SLACK``): reported, not refused.
    worst
        Up to ``n_worst`` cells of smallest q after: ``{"cell": index in the concatenation of the
        mesh's cell blocks, "type", "quality", "quality_before", "centroid": [x, y, z] after,
        "failed": bool}``.
    worst_nodes
        Up to ``n_worst`` nodes of largest orthogonality loss (or smallest value without a before):
        ``{"node", "before", "after", "point": [x, y, z] after, "failed"}``.
    input_bad
        Up to ``n_worst`` cells inverted or degenerate in the input: ``{"cell", "type", "quality",
        "centroid"}`` (input coordinates).
    surface_cells
        2-D cells of a surface in space (not in one plane: a wing's skin read as a mesh), not judged:
        they have no volume (``count`` is then 0).
    """

    count: int
    n_inverted: int
    n_below: int
    threshold: float
    relative: float
    min_before: float | None
    min_after: float | None
    n_inverted_before: int | None = None
    n_below_before: int | None = None
    n_input_bad: int = 0
    n_new_inverted: int = 0
    n_worse: int = 0
    n_nodes: int = 0
    ortho_min: float = DEFAULT_ORTHO_MIN
    ortho_loss_max: float = DEFAULT_ORTHO_LOSS
    ortho_before: float | None = None
    ortho_after: float | None = None
    ortho_loss: float | None = None
    n_ortho_low: int = 0
    n_ortho_low_before: int | None = None
    n_ortho_failed: int = 0
    n_design_cells: int = 0
    n_design_nodes: int = 0
    collapse: float = DEFAULT_COLLAPSE
    worst: list = field(default_factory=list)
    worst_nodes: list = field(default_factory=list)
    input_bad: list = field(default_factory=list)
    #: Polyhedral cells (:mod:`ffdcli.quality.polyhedral`): faces refused by the face rule, and
    #: checkMesh's figures after and before (``{"after", "before", "faces_failed", "worst_faces"}``).
    n_faces_failed: int = 0
    polyhedral: dict | None = None
    surface_cells: int = 0

    @property
    def relative_check(self) -> bool:
        """True when there was a mesh before (``ffd deform``), False for ``ffd check``."""
        return self.min_before is not None or self.n_inverted_before is not None

    @property
    def collapse_floor(self) -> float | None:
        """The quality under which a cell made worse fails: min(collapse, the input's worst)."""
        return None if self.min_before is None else min(self.collapse, self.min_before)

    @property
    def n_failed(self) -> int:
        """What the gate refuses on (cells inverted by the design, made worse; nodes that lost
        orthogonality). Without a mesh before: the inverted or degenerate cells."""
        if not self.relative_check:
            return self.n_inverted
        return self.n_new_inverted + self.n_worse + self.n_ortho_failed + self.n_faces_failed

    @property
    def ok(self) -> bool:
        return self.n_failed == 0

    def rule(self) -> str:
        """The gate's rule in words, for messages."""
        return (f"a cell fails when the design inverts it, or when its scaled Jacobian falls below "
                f"{self.threshold:g}, below {self.relative:g} x its value before and below "
                f"{fmt_g(self.collapse_floor)} (the lower of {self.collapse:g} and the input mesh's worst); "
                f"a node fails when its orthogonality falls below "
                f"{self.ortho_min:g} deg after losing more than {self.ortho_loss_max:g} deg; "
                f"unless the design's own FFD map shapes the cell or node so (within {DESIGN_SLACK:g} x "
                f"its quality, {DESIGN_SLACK_DEG:g} deg)"
                + ("" if self.polyhedral is None else
                   f"; of polyhedral cells (quality: the smallest cosine between a face and its centre's "
                   f"line), a face fails when its non-orthogonality exceeds {90 - self.ortho_min:g} deg and the "
                   f"input's worst after growing by more than {self.ortho_loss_max:g} deg, or its skewness "
                   f"exceeds 4 and the input's worst and {1 / self.relative:g} x its value before"))

    def to_dict(self) -> dict:
        """The report for ``--json`` (the same keys for ``deform`` and ``check``)."""
        return {"cells": self.count, "inverted": self.n_inverted, "below_threshold": self.n_below,
                "threshold": self.threshold, "relative": self.relative, "collapse": self.collapse,
                "min_before": self.min_before,
                "min_after": self.min_after, "inverted_before": self.n_inverted_before,
                "below_threshold_before": self.n_below_before, "input_degenerate": self.n_input_bad,
                "inverted_by_design": self.n_new_inverted, "made_worse": self.n_worse,
                "shaped_by_design": {"cells": self.n_design_cells, "nodes": self.n_design_nodes},
                "orthogonality": {"nodes": self.n_nodes, "min_before": self.ortho_before,
                                  "min_after": self.ortho_after, "largest_loss": self.ortho_loss,
                                  "below_min": self.n_ortho_low, "below_min_before": self.n_ortho_low_before,
                                  "failed": self.n_ortho_failed, "min": self.ortho_min,
                                  "loss": self.ortho_loss_max},
                "failed": self.n_failed, "ok": self.ok, "worst": self.worst, "worst_nodes": self.worst_nodes,
                "input_bad": self.input_bad, "surface_cells": self.surface_cells,
                **({} if self.polyhedral is None else {"polyhedral": self.polyhedral})}

    def summary(self) -> str:
        """One line for people: the same words for ``ffd deform`` and ``ffd check``."""
        rel = self.relative_check
        before = f"{fmt_g(self.min_before)} before, " if rel else ""
        after = fmt_g(self.min_after) + (" after" if rel else "")
        measure = "scaled Jacobian" if self.polyhedral is None else "face pyramids, cosine"
        text = (f"cell quality ({measure}): min {before}{after}; {self.count} cells: "
                f"{self.n_inverted} inverted or degenerate, {self.n_below} below {self.threshold:g}")
        if rel:
            text += f" ({self.n_below_before} before); {self.n_new_inverted} inverted by the design, " \
                    f"{self.n_worse} made worse"
        if self.n_nodes:
            ob = f"{fmt_g(self.ortho_before, '.1f')} before, " if rel else ""
            oa = fmt_g(self.ortho_after, ".1f") + (" after" if rel else "")
            text += (f". orthogonality (SU2): min {ob}{oa} deg; {self.n_ortho_low} nodes below "
                     f"{self.ortho_min:g} deg")
            if rel:
                text += (f" ({self.n_ortho_low_before} before), largest loss {fmt_g(self.ortho_loss, '.1f')} deg, "
                         f"{self.n_ortho_failed} nodes lost orthogonality")
        if self.n_design_cells or self.n_design_nodes:
            text += (f"; shaped by the design's own map (accepted): {self.n_design_cells} cells, "
                     f"{self.n_design_nodes} nodes")
        if self.polyhedral is not None:
            text += _polyhedral_words(self.polyhedral)
        return text

    def describe_worst(self, n: int = 5) -> str:
        """The worst failing cells and nodes, one per line: id, type, values and where."""
        lines = []
        for w in [w for w in self.worst if w["failed"]][:n]:
            before = "" if w["quality_before"] is None else f" (before {w['quality_before']:.3g})"
            lines.append(f"  cell {w['cell']} ({w['type']}): quality {w['quality']:.3g}{before} "
                         f"at {fmt_xyz(w['centroid'])}")
        for w in [w for w in self.worst_nodes if w["failed"]][:n]:
            lines.append(f"  node {w['node']}: orthogonality {w['after']:.1f} deg (before {w['before']:.1f}) "
                         f"at {fmt_xyz(w['point'])}")
        return "\n".join(lines)

    def failure_message(self) -> str:
        """What failed, the rule and the worst place, in one line (for the exit-3 message)."""
        what = []
        if self.n_new_inverted:
            what.append(f"{self.n_new_inverted} cells inverted by the design")
        if self.n_worse:
            what.append(f"{self.n_worse} cells made worse")
        if self.n_ortho_failed:
            what.append(f"{self.n_ortho_failed} nodes lost orthogonality")
        if self.n_faces_failed:
            what.append(f"{self.n_faces_failed} faces made severely non-orthogonal or skewed")
        worst = self.describe_worst(1).strip().splitlines()
        where = f"; worst: {worst[0].strip()}" if worst else ""
        return f"{', '.join(what) or 'no failure'} of {self.count} cells ({self.rule()}){where}"


def _polyhedral_words(p: dict) -> str:
    """checkMesh's figures of a polyhedral mesh, after (and before), for the summary line."""
    a, b = p["after"], p.get("before")

    def pair(key, spec):
        return format(a[key], spec) + (f" (before {format(b[key], spec)})" if b else "")

    text = (f". checkMesh's figures: {a['negative_volumes']} negative volumes, {a['face_pyramid_errors']} face "
            f"pyramid errors, max non-orthogonality {pair('max_non_orthogonality', '.4g')} deg, "
            f"{a['severely_non_orthogonal']} faces above 70 deg, max skewness {pair('max_skewness', '.4g')}, "
            f"{a['skewed_faces']} faces above 4")
    if b:
        text += f"; {p['faces_failed']} faces made severely non-orthogonal or skewed"
    return text


def fmt_g(v, spec: str = ".3g") -> str:
    return "n/a" if v is None else format(v, spec)


def fmt_xyz(p) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in p) + ")"
