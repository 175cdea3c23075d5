"""The volume warp beside another revision of ffd, in one run: the gain as a ratio that the
machine's speed and load do not change.

``python -m benchmarks.versus REV [--repeats N] [--quick]`` checks REV out into a temporary git
worktree and runs, alternately in this checkout and in REV's (each with its own sources on
``PYTHONPATH`` and its own numba cache, warmed by an untimed first run):

* the layered warp of ``benchmarks/bench_warp.py`` (``--child 1000000 50000 5000``: 1M volume / 50k
  surface nodes; its first warp on the model, which includes what the model keeps, and the error
  against the exact sum on 5,000 nodes);
* ``ffd deform`` of the 1M-node extruded wing of ``benchmarks/bench_pipeline.py`` with the IDW warp
  (box cached by an untimed ``ffd box`` in each checkout; the same mesh file for both): "ffd deform"
  is a deform after the first (what a loop over designs pays: the box and, where the revision keeps
  them, the warp's reference weights read from their caches), "ffd deform, first" the first deform
  of the mesh (the warp's cache removed before it; the box's kept).

It prints one table: per case the min and max wall time of each side, the ratio of the minima and
of the maxima. ``--quick``: 100k volume nodes and a smaller wing (a check of the script, not the
targets).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.bench_pipeline import FULL, QUICK, build_case

REPO = Path(__file__).resolve().parents[1]


def _run(checkout: Path, args: list[str], cwd: Path) -> tuple[float, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(checkout) + os.pathsep + env.get("PYTHONPATH", "")
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, *args], cwd=cwd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{checkout}: {' '.join(args)} exit {proc.returncode}: "
                           f"{proc.stderr.strip().splitlines()[-3:]}")
    return wall, proc.stdout


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rev", help="the other revision (a commit, tag or branch of this repository)")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    n_vol = "100000" if a.quick else "1000000"
    with tempfile.TemporaryDirectory(prefix="ffd-versus-") as tmp:
        tmp = Path(tmp)
        other = tmp / "other"
        subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", "-q", str(other), a.rev], check=True)
        try:
            sides = {"this": REPO, a.rev: other}
            cases = {}
            print("building the extruded wing ...", file=sys.stderr)
            facts = build_case(tmp, QUICK if a.quick else FULL)
            for name, root in sides.items():
                work = tmp / f"case-{name.replace('/', '_')}"
                work.mkdir()
                for f in ("wing.su2", "design_idw.yaml"):
                    (work / f).symlink_to(tmp / f) if f == "wing.su2" else (work / f).write_text((tmp / f).read_text())
                (work / "out").mkdir()
                print(f"{name}: compiling and caching the box (untimed) ...", file=sys.stderr)
                _run(root, ["-m", "ffdcli", "box", "design_idw.yaml", "--json"], work)
                _run(root, ["-m", "ffdcli", "deform", "design_idw.yaml", "--json", "--force"], work)
                cases[name] = work
            rows: dict[tuple[str, str], list[float]] = {}
            errs: dict[str, float] = {}
            for rep in range(a.repeats):
                for name, root in sides.items():
                    print(f"repeat {rep + 1}/{a.repeats}: {name} ...", file=sys.stderr)
                    _, out = _run(root, ["-m", "benchmarks.bench_warp", "--child", n_vol, "50000", "5000"], root)
                    r = json.loads(out.strip().splitlines()[-1])
                    first = r.get("warp_first_s", r["warp_s"])
                    rows.setdefault(("layered warp", name), []).append(r["prepare_s"] + first)
                    errs[name] = r["err_max"]
                    wall, _ = _run(root, ["-m", "ffdcli", "deform", "design_idw.yaml", "--json", "--force"],
                                   cases[name])
                    rows.setdefault(("ffd deform", name), []).append(wall)
                    for f in cases[name].glob("*.ffdwarp.npz"):      # the first deform of a mesh
                        f.unlink()
                    wall, _ = _run(root, ["-m", "ffdcli", "deform", "design_idw.yaml", "--json", "--force"],
                                   cases[name])
                    rows.setdefault(("ffd deform, first", name), []).append(wall)
        finally:
            subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(other)], check=False)
    this, rev = list(sides)
    print(f"\nThis checkout against {rev}, alternating, {a.repeats} runs each; "
          f"{facts['nodes']:,} mesh nodes / {facts['wing_nodes']:,} wing nodes; load now "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores\n")
    print(f"| case | this (min-max) | {rev} (min-max) | ratio of minima | ratio of maxima |")
    print("|---|---|---|---|---|")
    for case in ("layered warp", "ffd deform", "ffd deform, first"):
        t, o = rows[(case, this)], rows[(case, rev)]
        print(f"| {case} | {min(t):.2f}-{max(t):.2f} s | {min(o):.2f}-{max(o):.2f} s | "
              f"**{min(o) / min(t):.2f}x** | {max(o) / max(t):.2f}x |")
    print(f"\nlayered warp error (largest, of the largest move, 5,000 nodes): this {errs[this]:.2e}, "
          f"{rev} {errs[rev]:.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
