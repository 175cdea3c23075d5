"""This tree beside another checkout of ffd, in one run: ``python -m benchmarks.beside OTHER [--rounds N]``.

For a refactoring that must not change behaviour: the same commands run from both trees,
alternately (old, new, old, new, ...) so that the machine's load falls on both alike, each tree with its
own sources (``PYTHONPATH``) and numba cache and this interpreter. Prints one Markdown table: each
command's wall time in each tree (min and max of ``--rounds``, after one untimed run that fills the
caches), the ratio of the minima (this tree / the other), and whether the outputs are byte for byte
the same (the deformed mesh and the lattice; ``-`` for a command without a file output).

The commands are the bundled samples' main jobs (``ffd deform`` of designs that exist in both trees,
``ffd box``, ``ffd check``), DesignModel's reverse products in process (``benchmarks/bench_model_vjp.py``,
this tree's script run on each tree's sources) and the embedding benchmark's in-process kernel timing
(``python -m benchmarks --only core --quick``, its own table printed by each tree, not compared here).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent

#: (label, arguments after ``python -m ffdcli``, output files compared). ``{out}``: the run's folder.
COMMANDS = (
    ("deform rect_twist_linear (2,778 pts)", ["deform", "configs/rect_twist_linear.yaml", "-q", "-o",
                                              "{out}/a.su2"], ["a.su2", "a_lattice.vtk"]),
    ("deform rect_shape_random", ["deform", "configs/rect_shape_random.yaml", "-q", "-o", "{out}/b.su2"],
     ["b.su2", "b_lattice.vtk"]),
    ("deform crm_twist_tip", ["deform", "configs/crm_twist_tip.yaml", "-q", "-o", "{out}/c.su2"],
     ["c.su2", "c_lattice.vtk"]),
    ("deform wing_body", ["deform", "configs/wing_body.yaml", "-q", "-o", "{out}/d.su2"], ["d.su2", "d_lattice.vtk"]),
    ("deform wing_tail_fin", ["deform", "configs/wing_tail_fin.yaml", "-q", "-o", "{out}/e.su2"],
     ["e.su2", "e_lattice.vtk"]),
    ("deform naca0012_s1223 (2D)", ["deform", "configs/naca0012_s1223.yaml", "-q", "-o", "{out}/f.su2"],
     ["f.su2", "f_lattice.vtk"]),
    ("check crm_wing", ["check", "samples/crm_wing.su2", "-q"], []),
    ("DesignModel set_values + surface_vjp + mesh_vjp x2 (in process, median)",
     ["@script", "benchmarks/bench_model_vjp.py"], []),
    ("box crm_wing, rebuilt (fit + embed)", ["box", "samples/crm_wing.su2", "--surface", "wing", "--rebuild", "-q",
                                             "--cache-dir", "{out}", "--lattice", "{out}/g_lattice.vtk"],
     ["g_lattice.vtk"]),
)


def _digest(path: Path) -> str | None:
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None


def _outputs(folder: Path, files: list[str]) -> list[str]:
    """The names among ``files`` found in ``folder``, a lattice ``X_lattice.vtk`` standing for the
    per-component ``X_lattice_<name>.vtk`` files of a design with components."""
    names = []
    for f in files:
        if f.endswith("_lattice.vtk") and not (folder / f).exists():
            names += sorted(p.name for p in folder.glob(f[:-4] + "_*.vtk"))
        elif (folder / f).exists():
            names.append(f)
    return names


def run_once(tree: Path, args: list[str], out: Path) -> tuple[float, int]:
    """Wall seconds and exit code of ``python -m ffdcli ARGS`` in ``tree``. ``["@script", PATH]``: this
    tree's script ``PATH`` run with ``tree``'s sources, its seconds the ``"seconds"`` of the JSON line it
    prints (an in-process timing of the public API, the same script for both trees)."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    env.pop("NUMBA_CACHE_DIR", None)                 # each tree's own cache beside its sources
    script = args[0] == "@script"
    cmd = ([sys.executable, str(HERE / args[1]), *args[2:]] if script else
           [sys.executable, "-m", "ffdcli", *(a.format(out=out) for a in args)])
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=tree, env=env, stdout=subprocess.PIPE if script else subprocess.DEVNULL,
                       stderr=subprocess.PIPE, text=True)
    seconds = time.perf_counter() - t0
    if script and p.returncode == 0:
        seconds = float(json.loads(p.stdout.strip().splitlines()[-1])["seconds"])
    if p.returncode != 0:
        print(f"  {tree.name}: {' '.join(cmd[3:])} exited {p.returncode}: {p.stderr.strip()[-300:]}",
              file=sys.stderr)
    return seconds, p.returncode


def compare(other: Path, rounds: int) -> list[dict]:
    """One row per command (see the module docstring)."""
    trees = {"other": other.resolve(), "this": HERE}
    rows = []
    with tempfile.TemporaryDirectory(prefix="ffd-beside-") as tmp:
        for label, args, files in COMMANDS:
            if args[0] == "deform" and not (trees["other"] / args[1]).exists():
                rows.append({"command": label, "note": "not in the other tree"})
                continue
            outs = {k: Path(tmp) / k / label.split()[1] for k in trees}
            for o in outs.values():
                o.mkdir(parents=True, exist_ok=True)
            times: dict[str, list[float]] = {k: [] for k in trees}
            codes = {}
            for k, tree in trees.items():             # fill the caches (box, numba), untimed
                codes[k] = run_once(tree, args, outs[k])[1]
            same = all(_digest(outs["this"] / f) == _digest(outs["other"] / f) for f in _outputs(outs["other"], files))
            same = same and bool(_outputs(outs["other"], files))
            for _ in range(rounds):
                for k, tree in trees.items():
                    for f in files:
                        (outs[k] / f).unlink(missing_ok=True)
                    times[k].append(run_once(tree, args, outs[k])[0])
            rows.append({"command": label, "other_min": min(times["other"]), "other_max": max(times["other"]),
                         "this_min": min(times["this"]), "this_max": max(times["this"]),
                         "ratio": min(times["this"]) / min(times["other"]),
                         "same": ("yes" if same else "NO") if files else "-",
                         "exit": f"{codes['other']}/{codes['this']}"})
            print(f"  {label}: {rows[-1]['this_min']:.2f} s beside {rows[-1]['other_min']:.2f} s", file=sys.stderr)
    return rows


def table(rows: list[dict], other: Path, rounds: int) -> str:
    head = (f"This tree ({HERE.name}) beside {other} in one run, commands alternated, {rounds} timed rounds "
            f"each after a cache-filling run; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load "
            f"average {' / '.join(f'{x:.2f}' for x in os.getloadavg())}.\n\n"
            "| command | other (min-max s) | this (min-max s) | this / other | outputs byte-identical | exit |\n"
            "|---|---|---|---|---|---|\n")
    lines = []
    for r in rows:
        if "note" in r:
            lines.append(f"| {r['command']} | {r['note']} | | | | |")
            continue
        lines.append(f"| {r['command']} | {r['other_min']:.2f}-{r['other_max']:.2f} | {r['this_min']:.2f}-"
                     f"{r['this_max']:.2f} | {r['ratio']:.2f} | {r['same']} | {r['exit']} |")
    return head + "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("other", type=Path, help="the other checkout (a git worktree of an older commit)")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    if not (a.other / "ffdcli" / "__main__.py").is_file():
        print(f"beside: {a.other} is not a checkout of ffd (no ffdcli/__main__.py)", file=sys.stderr)
        return 2
    if shutil.which("git"):
        for tree in (a.other, HERE):
            rev = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True,
                                 text=True).stdout.strip()
            print(f"{tree}: {rev}", file=sys.stderr)
    print(table(compare(a.other, a.rounds), a.other, a.rounds))
    return 0


if __name__ == "__main__":
    sys.exit(main())
