"""A design loop with SU2: ffd deforms, SU2_CFD solves, SU2's sensitivities come back through `ffd grad`.

    python examples/su2_design_loop.py DESIGN.yaml SU2.cfg [--variable c0.twist.tip] [--values 0,2,4]
                                       [--adjoint SU2_ADJ.cfg] [--work DIR] [--dry-run]

For each value of one design variable: ``ffd deform`` writes the mesh, SU2_CFD runs on it (the config's
``MESH_FILENAME`` is replaced by the deformed mesh, ``MESH_OUT_FILENAME`` is not touched), and the
last row of SU2's ``history.csv`` is read for the lift and drag coefficients. With ``--adjoint``,
SU2_CFD_AD and SU2_DOT_AD then run with that config, and ``ffd grad`` turns their ``surface_sens.csv``
(or ``volume_sens.csv``) into dJ/d(every design variable). ``--dry-run`` runs the ffd steps and prints
the SU2 commands instead of running them (what the test suite does when SU2 is not installed).

See docs/su2.md for what the SU2 configs need (markers unchanged; a wing with span along z needs a
sideslip). The loop keeps every case in its own folder under ``--work`` (default ``out/su2_loop``).
"""

from __future__ import annotations

import argparse
import csv
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import yaml


def ffd(*args: str) -> dict:
    """Run ``ffd ARGS --json`` in this interpreter's environment; the parsed summary."""
    proc = subprocess.run([sys.executable, "-m", "ffdcli", *args, "--json"], capture_output=True, text=True)
    if proc.returncode != 0:
        sys.exit(f"ffd {' '.join(args)} failed (exit {proc.returncode}):\n{proc.stderr}")
    return json.loads(proc.stdout)


def with_mesh(cfg_text: str, mesh: Path) -> str:
    """The SU2 config with ``MESH_FILENAME=`` pointing at ``mesh`` (added if the config has none)."""
    line = f"MESH_FILENAME= {mesh}"
    if re.search(r"(?m)^\s*MESH_FILENAME\s*=", cfg_text):
        return re.sub(r"(?m)^\s*MESH_FILENAME\s*=.*$", line, cfg_text)
    return cfg_text + "\n" + line + "\n"


def su2(program: str, cfg: Path, folder: Path, dry_run: bool) -> None:
    cmd = [program, cfg.name]
    if dry_run:
        print(f"    (dry run) in {folder}: {' '.join(cmd)}")
        return
    with open(folder / f"{program}.log", "w") as log:
        proc = subprocess.run(cmd, cwd=folder, stdout=log, stderr=subprocess.STDOUT)
    if proc.returncode != 0:
        sys.exit(f"{program} failed in {folder} (see {program}.log)")


def last_history(folder: Path) -> dict:
    """The last row of SU2's history.csv as {column: value} (names stripped of quotes and blanks)."""
    path = next(iter(sorted(folder.glob("history*.csv"))), None)
    if path is None:
        return {}
    with open(path) as fh:
        rows = list(csv.reader(fh))
    names = [n.strip().strip('"') for n in rows[0]]
    return dict(zip(names, (v.strip() for v in rows[-1]), strict=False))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("design", type=Path)
    ap.add_argument("config", type=Path, help="SU2_CFD config of the flow (its MESH_FILENAME is replaced)")
    ap.add_argument("--variable", default=None,
                    help="design variable to sweep, e.g. c0.twist.tip (default: the first change)")
    ap.add_argument("--values", default="0,2,4", help="comma-separated values of the variable")
    ap.add_argument("--adjoint", type=Path, help="SU2_CFD_AD/SU2_DOT_AD config: also compute dJ/dv")
    ap.add_argument("--work", type=Path, default=Path("out/su2_loop"))
    ap.add_argument("--dry-run", action="store_true", help="run ffd only; print the SU2 commands")
    a = ap.parse_args(argv)
    if not a.dry_run and shutil.which("SU2_CFD") is None:
        sys.exit("SU2_CFD is not on the PATH (use --dry-run to see the steps without SU2)")

    key = _set_key(a.design, a.variable)
    name = a.variable or key
    results = []
    for value in [float(v) for v in a.values.split(",")]:
        folder = (a.work / f"{name}={value:g}").resolve()
        folder.mkdir(parents=True, exist_ok=True)
        mesh = folder / "mesh.su2"
        summary = ffd("deform", str(a.design), "--set", f"{key}={value}", "-o", str(mesh),
                      "--lattice", str(folder / "lattice.vtk"))
        print(f"{name} = {value:g}: deformed, max surface displacement {summary['max_displacement']:.4g}")
        cfg = folder / "flow.cfg"
        cfg.write_text(with_mesh(a.config.read_text(), mesh))
        su2("SU2_CFD", cfg, folder, a.dry_run)
        row = {"value": value, **{k: last_history(folder).get(k) for k in ("CL", "CD")}}
        if a.adjoint is not None:
            adj = folder / "adjoint.cfg"
            adj.write_text(with_mesh(a.adjoint.read_text(), mesh))
            su2("SU2_CFD_AD", adj, folder, a.dry_run)
            su2("SU2_DOT_AD", adj, folder, a.dry_run)
            sens = next((folder / n for n in ("volume_sens.csv", "surface_sens.csv") if (folder / n).exists()),
                        None)
            if sens is not None:
                row["gradient"] = ffd("grad", str(a.design), "--set", f"{key}={value}", "--sens", str(sens))
        results.append(row)
    (a.work / "results.json").write_text(json.dumps(results, indent=2))
    print(f"wrote {a.work / 'results.json'}")
    return 0


def _set_key(design: Path, name: str | None) -> str:
    """The --set key of a variable name like ``c0.twist.tip`` or ``c1.span`` (scalars and {root, tip})."""
    changes = yaml.safe_load(design.read_text()).get("changes") or []
    if name is None:
        if not changes:
            sys.exit(f"{design} has no changes to sweep")
        (kind, spec), = changes[0].items()
        return f"changes.0.{kind}" + (".tip" if isinstance(spec, dict) and "tip" in spec else "")
    m = re.fullmatch(r"c(\d+)\.(\w+)(?:\.(\w+))?(?:\[(\d+)\])?", name)
    if m is None:
        sys.exit(f"cannot sweep {name!r}: give a variable like c0.twist.tip or c1.span")
    index, kind, sub, pos = m.groups()
    key = f"changes.{index}.{kind}"
    if sub:
        key += f".{sub}"
    if pos is not None:
        key += f".{pos}"
    return key


if __name__ == "__main__":
    raise SystemExit(main())
