"""What the rigid wall layer costs: ``ffd deform``'s own time on a RANS mesh with and without it.

The mesh: the generated 32-prism-layer wing of the robustness table (``gmsh_wings`` case
``rect_z_rans32``: 98k nodes, first cell 1e-6 chord; built with gmsh into ``--work`` once). The design:
``twist: {tip: 10}`` on a 6 x 8 x 2 lattice (the box cached before the timed runs). Each round loads
the design afresh (:func:`ffdcli.app.run.load_run`, untimed) and times
:func:`ffdcli.app.deformation.deform` (the warp's preparation, the wall layer's detection and motion,
the volume, the quality gate and the first-cell report; the box and the warp's reference weights read
from their caches, as a second ``ffd deform`` of the mesh reads them) once with ``volume.wall_layer: none`` and once
with ``rigid``, one after the other in one process, in CPU seconds of the process
(``time.process_time``: the machine may be shared, and wall seconds then measure the neighbours). Printed:
each round's ratio rigid / none and the smallest and largest over the rounds, beside the target 1.3.
One untimed round first compiles and warms the kernels.

The same rounds follow with no cache read or written (each run as the first of the mesh: the reference
weights and the layer computed in it), then as a first ``ffd deform`` of the mesh is (the box's cache
read, no warp cache: the run computes the weights and the layer and writes them, each run into a folder
of its own).

``python -m benchmarks.bench_wall_layer [--rounds 5] [--work DIR] [--profile] [--cold]`` (``--profile``: the
rigid runs' stages, CPU seconds of each, summed over the rounds; ``--cold``: the first-run rounds only);
also part of ``make bench``.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import shutil
import sys
import tempfile
import time
from pathlib import Path

import yaml

TITLE = "The rigid wall layer's cost: ffd deform on a 32-prism-layer wing with and without it"
REPO = Path(__file__).resolve().parents[1]
TARGET = 1.3
CASE = "rect_z_rans32"
DESIGN = [{"twist": {"tip": 10}}]
#: How each set of rounds is named.
WHAT = {True: "caches read", False: "first run, no cache", "written": "first run, cache written"}


def _design(work: Path) -> Path:
    from ffdcli.testing import gmsh_wings

    mesh = gmsh_wings.write_case(CASE, work / "meshes")
    folder = work / "designs" / "wall_layer_cost"
    folder.mkdir(parents=True, exist_ok=True)
    (work / "cache").mkdir(exist_ok=True)        # the box and the warp's reference weights kept, as ffd deform does
    path = folder / "twist_tip10.yaml"
    path.write_text(yaml.safe_dump({"mesh": str(mesh), "surface": "wing", "box": {"points": [6, 8, 2]},
                                    "changes": DESIGN, "output": {"mesh": str(folder / "out.su2")}},
                                   sort_keys=False))
    return path


def _one(path: Path, mode: str, work: Path, profile: cProfile.Profile | None = None, cached=True) -> float:
    """CPU seconds of one ``deform`` with ``volume.wall_layer: mode`` (the run loaded untimed; ``cached``
    False: no cache read or written, as a first run of the mesh; "written": the box's cache read, the
    warp's computed and written into a folder of the run's own, as a first ``ffd deform`` of the mesh)."""
    from ffdcli.app.deformation import deform
    from ffdcli.app.run import load_run
    from ffdcli.design import load_design

    with tempfile.TemporaryDirectory(prefix="ffd-wall-layer-") as tmp:
        folder = work / "cache"
        if cached == "written":
            for box in folder.glob("*.ffdcache.npz"):
                shutil.copy(box, tmp)
            folder = Path(tmp)
        run = load_run(load_design(path, overrides=[f"volume.wall_layer={mode}"]), cache_dir=folder,
                       use_cache=bool(cached))
        if profile is not None:
            profile.enable()
        t0 = time.process_time()
        deform(run)
        dt = time.process_time() - t0
        if profile is not None:
            profile.disable()
    return dt


def measure(rounds: int = 5, work: Path | None = None, profile: bool = False, cached=True) -> dict:
    """``{"none": [s, ...], "rigid": [s, ...], "ratio": [...]}``: CPU seconds of each round, alternating
    (``cached`` False: every run as the first of the mesh, its warp's reference weights and wall layer
    computed; "written": and written to a cache file, :func:`_one`)."""
    work = work or REPO / "out" / "robustness"
    path = _design(work)
    for mode in ("none", "rigid"):          # compile (and write the caches) untimed
        _one(path, mode, work, cached=cached)
    prof = cProfile.Profile(time.process_time) if profile else None
    out = {"none": [], "rigid": []}
    for k in range(rounds):
        order = ("none", "rigid") if k % 2 == 0 else ("rigid", "none")
        for mode in order:
            out[mode].append(_one(path, mode, work, prof if mode == "rigid" else None, cached))
    out["ratio"] = [r / n for r, n in zip(out["rigid"], out["none"], strict=True)]
    if prof is not None:
        out["profile"] = prof
    return out


def _rows(m: dict, what: str = "caches read") -> list[dict]:
    ratio = m["ratio"]
    return [{"case": f"ffd deform CPU s, wall_layer none ({CASE}, {what}, {len(ratio)} rounds, min-max)",
             "measured": f"{min(m['none']):.3f}-{max(m['none']):.3f}"},
            {"case": f"ffd deform CPU s, wall_layer rigid ({what}, min-max)",
             "measured": f"{min(m['rigid']):.3f}-{max(m['rigid']):.3f}"},
            {"case": f"rigid / none, each round ({what}, min-max)", "measured": f"{min(ratio):.2f}-{max(ratio):.2f}",
             "target": f"<= {TARGET}", "met": max(ratio) <= TARGET}]


def run(quick: bool = False) -> list[dict]:
    """Rows for ``python -m benchmarks``."""
    n = 3 if quick else 5
    return (_rows(measure(n)) + _rows(measure(n, cached=False), "first run, no cache")
            + _rows(measure(n, cached="written"), WHAT["written"]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_wall_layer", description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5, help="alternating rounds (default 5)")
    ap.add_argument("--work", type=Path, default=REPO / "out" / "robustness",
                    help="folder of the generated mesh, design and box cache (default out/robustness)")
    ap.add_argument("--profile", action="store_true", help="also print the rigid runs' stages (CPU seconds)")
    ap.add_argument("--cold", action="store_true", help="only the first-run rounds (no cache read)")
    args = ap.parse_args(argv)
    for cached in ([False, "written"] if args.cold else [True, False, "written"]):
        m = measure(args.rounds, args.work, args.profile, cached)
        what = WHAT[cached]
        for k, (n, r) in enumerate(zip(m["none"], m["rigid"], strict=True)):
            print(f"{what}, round {k + 1}: none {n:.3f} s  rigid {r:.3f} s  ratio {r / n:.3f}")
        for row in _rows(m, what):
            print(f"{row['case']}: {row['measured']}" + (f"  (target {row['target']})" if "target" in row else ""))
        if "profile" in m:
            pstats.Stats(m["profile"]).sort_stats("tottime").print_stats(20)
    return 0


if __name__ == "__main__":
    sys.exit(main())
