"""``python -m ffdcli.app.demo``: the paper's cases on the bundled samples, written to ``out/``.

Runs every design file of ``configs/`` that is a deformation (:func:`demo_cases`: deform, lattice
VTK, PNG), the NACA0012 -> S1223 fit, and writes ``out/index.md`` listing each case with its one-line
summary and picture. This is what ``make demo`` runs; the cases run side by side, one worker process
per core (:mod:`ffdcli.app.processes`), and print one line each as they finish.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import yaml

from ffdcli.app.deformation import deform
from ffdcli.app.fit import fit_design
from ffdcli.app.processes import default_jobs, run_steps
from ffdcli.app.run import load_run
from ffdcli.app.write import write_outputs
from ffdcli.design import load_design
from ffdcli.errors import FfdError
from ffdcli.io.atomic import atomic_write
from ffdcli.io.formats.airfoil import read_airfoil
from ffdcli.progress import no_progress
from ffdcli.viz.plot import plot_3d, plot_design

REPO = Path(__file__).resolve().parents[2]     # ffdcli/app/demo.py -> the repository
#: cases that also get the pyvista 3D view (each costs ~10-20 s off-screen here)
VIEW_3D = {"rect_twist_linear", "crm_twist_tip"}


def demo_cases(folder: Path) -> list[Path]:
    """The design files of ``folder`` the demo deforms, by name: all but the fit's input
    (``naca0012_s1223.yaml`` holds zero shape values: the fit case starts from it) and the inputs of
    ``ffd optimize`` (an ``optimize:`` section: their deformation is the baseline, and their meshes may
    need the solver's data first, e.g. ``onera_m6_optimize.yaml``'s generated mesh)."""
    out = []
    for c in sorted(Path(folder).glob("*.yaml")):
        if c.stem == "naca0012_s1223":
            continue
        spec = yaml.safe_load(c.read_text())
        if isinstance(spec, dict) and "optimize" in spec:
            continue
        out.append(c)
    return out


def run_case(config: Path, out: Path, progress, target=None) -> dict:
    """Deform one design into ``out`` (mesh, lattice, PNG); return its summary row.

    ``target``: a unit-chord airfoil (K, 2) drawn on the picture (the fit's target)."""
    t0 = time.perf_counter()
    design = load_design(config)
    stem = config.stem
    ext = Path(design.output["mesh"]).suffix or design.mesh.suffix
    run = load_run(design, progress=progress)
    result = deform(run, progress=progress)
    q = result.quality
    mesh_out = out / f"{stem}{ext}"
    lattice_out = out / f"{stem}_lattice.vtk"
    png = out / f"{stem}.png"
    ok = q is None or q.ok
    if ok:
        write_outputs(run, result, mesh_path=mesh_out, lattice_path=lattice_out)
    plot_design(run, result, png, target=target)
    png3d = None
    if stem in VIEW_3D:
        got = plot_3d(run, result, out / f"{stem}_3d.png")
        png3d = got.name if got else None
    return {
        "case": stem, "config": str(config.relative_to(REPO)) if config.is_relative_to(REPO) else str(config),
        "mesh": mesh_out.name if ok else None, "lattice": lattice_out.name if ok else None,
        "png": png.name, "png3d": png3d,
        "changes": "; ".join(f"{c.name + ': ' if c.name else ''}"
                             f"{', '.join(next(iter(x)) for x in c.spec.changes_spec) or 'none'}"
                             for c in run.components),
        "max_displacement": result.max_displacement,
        "quality": (q.summary() if ok else f"refused by the quality gate: {q.summary()}; "
                    f"{q.describe_worst(1).strip()}") if q is not None else "surface only",
        "seconds": time.perf_counter() - t0,
    }


def run_fit(out: Path, progress) -> dict | None:
    """NACA0012 -> S1223 by least squares (the paper's first case)."""
    config = REPO / "configs" / "naca0012_s1223.yaml"
    target = REPO / "samples" / "s1223.dat"
    t0 = time.perf_counter()
    fitted_yaml = out / "naca0012_s1223_fitted.yaml"
    rep = fit_design(config, target, fitted_yaml, progress=progress, force=True)

    row = run_case(fitted_yaml, out, progress, target=read_airfoil(target).coords)
    row["case"] = "naca0012_s1223_fit"
    row["changes"] = (f"shape fitted to S1223: max deviation {rep['before']['max']:.4f} -> "
                      f"{rep['after']['max']:.4f} chords")
    row["seconds"] = time.perf_counter() - t0
    return row


def write_index(rows: list[dict], out: Path) -> Path:
    lines = ["# ffd demo: the paper's cases on the bundled samples", "",
             "Original surface black, deformed red; lattice points grey (original) and red (deformed).", "",
             "| case | changes | max displacement | quality | mesh | lattice | seconds |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['case']} | {r['changes']} | {r['max_displacement']:.4g} | {r['quality']} | "
                     f"{r['mesh'] or '(refused)'} | {r['lattice'] or ''} | {r['seconds']:.1f} |")
    lines.append("")
    for r in rows:
        lines += [f"## {r['case']}", "", f"`{r['config']}`: {r['changes']}", "", f"![{r['case']}]({r['png']})", ""]
        if r.get("png3d"):
            lines += [f"![{r['case']} 3D]({r['png3d']})", ""]
    path = out / "index.md"
    with atomic_write(path, "w") as fh:
        fh.write("\n".join(lines))
    return path


def demo_step(kind: str, arg: str, out: str) -> dict:
    """One demo step in a worker (:func:`run_case` of a design file, or :func:`run_fit`); its summary
    row, or ``{"error": message}`` for a design that cannot run (the demo then stops with exit 2)."""
    try:
        if kind == "fit":
            return run_fit(Path(out), no_progress) or {}
        return run_case(Path(arg), Path(out), no_progress)
    except FfdError as e:
        return {"error": str(e)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ffdcli.app.demo", description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out", help="output folder (default: out)")
    ap.add_argument("--configs", default=str(REPO / "configs"), help="folder of design files")
    ap.add_argument("--only", nargs="*", help="case names (file stems) to run")
    ap.add_argument("-j", "--jobs", type=int, default=None,
                    help="cases side by side in worker processes (default: one per core; 1: one after the other)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    configs = demo_cases(Path(args.configs))
    if args.only:
        configs = [c for c in configs if c.stem in args.only]
    todo = [("case", str(c)) for c in configs]
    if not args.only or "naca0012_s1223_fit" in args.only:
        todo.insert(0, ("fit", ""))                          # the longest step first
    names = [Path(arg).stem if kind == "case" else "naca0012_s1223_fit" for kind, arg in todo]
    jobs = args.jobs or default_jobs(len(todo))
    print(f"ffd demo: {len(todo)} cases into {out}/, {jobs} at a time", flush=True)

    rows: dict[int, dict] = {}
    t0 = time.perf_counter()
    for k, (i, row) in enumerate(run_steps(demo_step, [(kind, arg, str(out)) for kind, arg in todo], jobs), 1):
        if "error" in row:
            print(f"[{k}/{len(todo)}] {names[i]}: error: {row['error']}", file=sys.stderr, flush=True)
            return 2
        if not row:
            continue
        rows[i] = row
        print(f"[{k}/{len(todo)}] {row['case']:<24} {row['changes']:<28} max disp {row['max_displacement']:.3g}"
              f"  {row['quality']}  ({row['seconds']:.1f} s)", flush=True)
    index = write_index([rows[i] for i in sorted(rows)], out)
    print(f"wrote {len(rows)} cases to {out}/ in {time.perf_counter() - t0:.1f} s; see {index}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
