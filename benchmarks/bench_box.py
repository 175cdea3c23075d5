"""The automatic box on a big surface: fitting must not cost more than embedding.

A swept, tapered, twisted wing surface of ~1M points (``ffdcli.testing.wings.wing_surface``); ``fit_box``
(section cuts, rectangles, embedding, margin check) against ``embed`` alone on the final lattice.
"""

from __future__ import annotations

import time

TITLE = "Automatic box on a big wing surface (benchmarks/bench_box.py)"
NOTES = "Target: the box's own work (cuts, fitting, rebuilds) adds no more than the embedding itself."


def _case(n_chord: int, n_span: int) -> dict:
    from ffdcli.box.box import fit_box
    from ffdcli.lattice.embedding import embed
    from ffdcli.mesh import CellBlock
    from ffdcli.settings import BoxSettings
    from ffdcli.testing.wings import Planform, wing_surface

    pf = Planform(le_sweep_deg=30, taper=0.3, twist_root_deg=2, twist_tip_deg=-4, dihedral_deg=5)
    pts, quads = wing_surface(pf, n_chord=n_chord, n_span=n_span)
    faces = [CellBlock("quad", quads)]
    t0 = time.perf_counter()
    box, emb, rep = fit_box(pts, faces, BoxSettings(points=(8, 6, 2)), dim=3)
    t_box = time.perf_counter() - t0
    t0 = time.perf_counter()
    embed(box.lattice(), pts)
    t_emb = time.perf_counter() - t0
    return {"surface points": len(pts), "ffd box (fit + embed) s": t_box, "embed alone s": t_emb,
            "box overhead / embed": (t_box - t_emb) / t_emb, "outside": int((~emb.inside).sum()),
            "rebuilds": rep["rebuilds"], "max residual": float(emb.residual.max())}


def run(quick: bool = False) -> list[dict]:
    _case(41, 21)                                  # compile the kernels outside the timing
    sizes = [(201, 126)] if quick else [(201, 126), (801, 626)]
    return [_case(*s) for s in sizes]
