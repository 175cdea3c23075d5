"""Where the add-material rule holds a Case 1 design, and at what price.

``ffd optimize --json`` ends with the best design's first-order optimality (``optimality``: each active
constraint item with ``d_objective_d_bound``, the objective's change per unit of its bound; see
docs/optimize.md). An ``add_material`` item is a wall node or a point between two (``between: k``);
this places each active item at its chord station and side and sums the prices in chord bands: where
the drag would fall if the section could lose material there, and how fast (dCD per chord of the
rule's margin), which is what stops the optimum.

    ffd optimize configs/adodg/case1_v32_dense.yaml --resume --json > out/adodg/case1_v32_dense.json
    python -m benchmarks.adodg.held configs/adodg/case1_v32_dense.yaml out/adodg/case1_v32_dense.json

A finished or running run's summary without solving: ``--resume --set optimize.iterations=0`` (the
baseline and the finished evaluations are read back; the best design with gradients is reported).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli.api import DesignModel
from ffdcli.constraints.add_material import AddMaterial
from ffdcli.errors import FfdError

#: An item is priced when its price is above this fraction of the largest (least squares leaves round-off).
PRICED = 1e-9
EDGES = (0.0, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)


@dataclass(frozen=True)
class Band:
    """The active items of one side in one chord band: ``side`` +1 upper, -1 lower; ``lo``, ``hi`` the
    band (x / chord); ``active`` items on the baseline; ``priced`` those with a price above :data:`PRICED`
    of the largest; ``price``
    their prices' sum (objective per chord of margin)."""

    side: int
    lo: float
    hi: float
    active: int
    priced: int
    price: float


def item_stations(model: DesignModel) -> tuple[str, np.ndarray, np.ndarray]:
    """The design's ``add_material`` constraint: its name prefix (``k0``), each item's chord station
    (C,) (x over the baseline section's chord, from its leading edge) and side (C,) (+1 upper, -1 lower),
    in the items' order (the nodes, then the points between them)."""
    found = [(i, c) for i, c in enumerate(model.constraints or []) if isinstance(c, AddMaterial)]
    if not found:
        raise ValueError("the design has no add_material constraint")
    i, c = found[0]
    pos = c.X0 if c.extra is None else np.vstack([c.X0, c.extra.points0])
    side = c.side if c.extra is None else np.concatenate([c.side, c.extra_side])
    x = pos[:, 0]
    lo, hi = c.X0[:, 0].min(), c.X0[:, 0].max()
    return f"k{i}", (x - lo) / (hi - lo), side.astype(int)


def bands(station: np.ndarray, side: np.ndarray, prices: dict[int, float], edges=EDGES) -> list[Band]:
    """The active items ``prices`` (item index -> price) summed per side and chord band ``edges``."""
    idx = np.fromiter(prices, dtype=int, count=len(prices))
    price = np.fromiter(prices.values(), dtype=float, count=len(prices))
    priced = np.abs(price) > PRICED * np.abs(price).max(initial=0.0)
    out = []
    for s in (1, -1):
        for k, (lo, hi) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
            last = k == len(edges) - 2
            inside = (side[idx] == s) & (station[idx] >= lo) & ((station[idx] <= hi) if last else (station[idx] < hi))
            out.append(Band(s, lo, hi, int(inside.sum()), int((inside & priced).sum()),
                            float(price[inside & priced].sum())))
    return out


def active_prices(summary: dict, prefix: str) -> dict[int, float]:
    """Item index -> price of the active items of constraint ``prefix`` in an ``ffd optimize --json``
    summary."""
    opt = summary.get("optimality")
    if not opt:
        raise ValueError("the summary has no 'optimality' (a run of an ffd without it, or no design with "
                         "gradients): make it again with --resume")
    return {int(a["name"].split("[")[1].rstrip("]")): float(a["d_objective_d_bound"])
            for a in opt["active"] if a["name"].startswith(prefix + ".")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("design", type=Path, help="the run's design file")
    ap.add_argument("summary", type=Path, help="its `ffd optimize --json` output (the last line is read)")
    args = ap.parse_args(argv)
    try:
        lines = [ln for ln in args.summary.read_text().splitlines() if ln.strip()]
        summary = json.loads(lines[-1])
    except (OSError, ValueError, IndexError) as e:
        print(f"held: cannot read the summary {args.summary}: {e}", file=sys.stderr)
        return 2
    try:
        prefix, station, side = item_stations(DesignModel.from_file(args.design))
        prices = active_prices(summary, prefix)
    except (FfdError, ValueError) as e:
        print(f"held: {args.design}, {args.summary}: {e}", file=sys.stderr)
        return 2
    opt = summary["optimality"]
    print(f"{args.summary}: at evaluation {opt['evaluation']} (the best design with gradients; the best "
          f"design's {opt['objective']} {summary['objective']['best']:.6g}): first-order residual "
          f"{opt['residual']:.3g}, {len(prices)} of {station.size} {prefix}.add_material items active")
    print(f"{'side':<6} {'x / chord':<11} {'active':>7} {'priced':>7} {'d' + opt['objective'] + '/d(margin)':>18}")
    for b in bands(station, side, prices):
        if b.active:
            print(f"{'upper' if b.side > 0 else 'lower':<6} {b.lo:4.2f}-{b.hi:4.2f}  {b.active:7d} {b.priced:7d} "
                  f"{b.price:18.4g}")
    others = [a for a in opt["active"] if not a["name"].startswith(prefix + ".") and a["d_objective_d_bound"]]
    for a in others:
        print(f"also: {a['name']} ({a['side']} {a['bound']:.6g}): {a['d_objective_d_bound']:.4g}")
    for b in opt["at_bounds"]:
        print(f"also: {b['variable']} at its {b['side']} bound {b['bound']:.6g}: {b['d_objective_d_bound']:.4g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
