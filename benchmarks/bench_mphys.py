"""ffd and pyGeo as the geometry of one MPhys run script, side by side.

``python -m benchmarks.bench_mphys`` (also a module of ``make bench``). The run script is
``examples/mphys_aero_wing.py``: MACH-Aero's aerodynamic script of its tutorial wing, with a stand-in
for ADflow (``examples/mphys_standin_aero.py``: two analytic functions of the surface coordinates, cl
and cd). It is run twice with only its geometry line swapped: ffd's ``FFDGeometry`` in ffd's
environment, pyGeo 1.17.1's ``OM_DVGEOCOMP`` in pyGeo's own (``FFD_PYGEO_PYTHON``, default
``~/pygeo-venv/bin/python`` with openmdao and mphys installed beside the wheels, see
``../shared/peers/README.md``). Both read the same surface points and one lattice: ffd's automatic box
of the wing, exported as the Plot3D FFD file pyGeo reads.

Three designs: the shape variable alone (every control point along z by a smooth function of where it
is, each tool computing its values from its own lattice), the twist alone (3 degrees at the tip, linear,
the root held), and both (where ``check_totals`` runs, forward and reverse, central differences, step
1e-5). Compared: the moved surface (max distance over the points, in root chords), cl and cd, and for
the twist the sections' incidence read back from the surface: ffd turns each section about its
trailing-edge line, pyGeo about its reference axis (the quarter chord of the box), so the surfaces
differ by a translation of each section while the incidence is the same. The thickness and volume
constraints are reported, not compared: each tool measures them its own way (ffd: the exact enclosed
volume, a grid of its sections; pyGeo: its projected grid between leList and teList).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.bench_pygeo import pygeo_python

TITLE = "ffd and pyGeo as the geometry of one MPhys run script (benchmarks/bench_mphys.py)"
REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "examples" / "mphys_aero_wing.py"
ROOT_CHORD = 5.0
CASES = {"shape": (0.0, 1.0), "twist": (3.0, 0.0), "both": (3.0, 1.0)}
#: Surface sizes (points a side from leading to trailing edge, stations): 1,200 and 64,000 points.
COARSE, FINE = (41, 15), (201, 161)


def _child(python: str, geometry: str, folder: Path, case: str, check: bool) -> dict:
    twist, shape = CASES[case]
    out = folder / f"{geometry}-{case}.json"
    cmd = [python, "-W", "ignore", str(SCRIPT), "run", str(folder), "--geometry", geometry, "--twist", str(twist),
           "--shape", str(shape), "--out", str(out)] + ([] if check else ["--no-check"])
    env = {"PYTHONPATH": str(REPO), "PATH": str(Path(python).parent) + ":/usr/bin:/bin",
           "OPENMDAO_REPORTS": "0", "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=folder, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{python} {case}: {proc.stderr.strip().splitlines()[-5:]}")
    data = json.loads(out.read_text())
    data["seconds"]["process"] = time.perf_counter() - t0
    return data


def incidence(X: np.ndarray, X0: np.ndarray) -> np.ndarray:
    """(stations,) degrees: the angle of each spanwise station's leading-to-trailing-edge line (stations:
    the points of one span coordinate y0; the edges: the least and largest x0 of the station)."""
    out = []
    for y in np.unique(np.round(X0[:, 1], 9)):
        rows = np.flatnonzero(np.abs(X0[:, 1] - y) < 1e-9)
        le, te = rows[np.argmin(X0[rows, 0])], rows[np.argmax(X0[rows, 0])]
        out.append(np.degrees(np.arctan2(X[le, 2] - X[te, 2], X[te, 0] - X[le, 0])))
    return np.array(out)


#: A block's error is |analytic - fd| / max(max|fd|, FLOOR): a derivative far below the outputs' size
#: (the thickness ratio's to the twist, ~5e-5 a degree) is not judged relative to its own round-off.
FLOOR = 1e-3


def _worst(check: dict) -> tuple[float, str]:
    """The largest |analytic - fd| / max(max|fd|, FLOOR) over the blocks, and which block."""
    worst, where = 0.0, ""
    for key, d in check.items():
        e = d["abs"] / max(d["fd"], FLOOR)
        if e > worst:
            worst, where = e, key
    return worst, where


def _prepare(folder: Path, size) -> None:
    subprocess.run([sys.executable, str(SCRIPT), "prepare", str(folder), "--size", *map(str, size)], check=True,
                   cwd=REPO, env={"PYTHONPATH": str(REPO), "PATH": str(Path(sys.executable).parent) + ":/usr/bin:/bin"})


def pygeo_mphys_python() -> str | None:
    """pyGeo's interpreter if its environment also has OpenMDAO and MPhys (``pip install openmdao 'mphys>=2,<3'``
    beside the wheels), else None."""
    py = pygeo_python()
    if py is None:
        return None
    ok = subprocess.run([py, "-c", "import pygeo.mphys, mphys"], capture_output=True).returncode == 0
    return py if ok else None


def run(quick: bool = False) -> list[dict]:
    py = pygeo_mphys_python()
    with tempfile.TemporaryDirectory(prefix="ffd-mphys-") as tmp:
        folder = Path(tmp)
        _prepare(folder, COARSE)
        X0 = np.load(folder / "surface.npz")["points"]
        ffd = {c: _child(sys.executable, "ffd", folder, c, c == "both") for c in CASES}
        pg = {c: _child(py, "pygeo", folder, c, c == "both") for c in CASES} if py else None
        fine = {}
        if not quick:            # the times on a finer surface (a RANS wall's count), no check_totals
            _prepare(folder / "fine", FINE)
            fine["ffd"] = _child(sys.executable, "ffd", folder / "fine", "both", False)
            fine["pyGeo"] = _child(py, "pygeo", folder / "fine", "both", False) if py else None
            fine["points"] = len(np.load(folder / "fine" / "surface.npz")["points"])
    rows = []
    for case in CASES:
        f = ffd[case]
        Xf = np.array(f["x_aero"])
        row = {"case": case, "ffd cl": f["cruise.cl"][0], "ffd cd": f["cruise.cd"][0],
               "ffd volume": f["geometry.volcon"][0], "ffd thickness min": min(f["geometry.thickcon"])}
        if pg:
            p = pg[case]
            Xp = np.array(p["x_aero"])
            row.update({"pyGeo cl": p["cruise.cl"][0], "pyGeo cd": p["cruise.cd"][0],
                        "pyGeo volume": p["geometry.volcon"][0], "pyGeo thickness min": min(p["geometry.thickcon"]),
                        "surface max diff / root chord": float(np.linalg.norm(Xf - Xp, axis=1).max() / ROOT_CHORD),
                        "incidence max diff (deg)": float(np.abs(incidence(Xf, X0) - incidence(Xp, X0)).max())})
        rows.append(row)
    f = ffd["both"]
    t = {"case": "times (s)", "ffd setup": f["seconds"]["setup"], "ffd run_model": f["seconds"]["run_model"],
         "ffd compute_totals rev": f["seconds"]["compute_totals_rev"],
         "ffd compute_totals fwd": f["seconds"]["compute_totals_fwd"]}
    if pg:
        p = pg["both"]
        t.update({"pyGeo setup": p["seconds"]["setup"], "pyGeo run_model": p["seconds"]["run_model"],
                  "pyGeo compute_totals rev": p["seconds"]["compute_totals_rev"],
                  "pyGeo compute_totals fwd": p["seconds"]["compute_totals_fwd"]})
    rows.append(t)
    for tool, r in ((k, v) for k, v in fine.items() if k != "points" and v):
        rows.append({"case": f"times (s), {fine['points']} points, {tool}", "setup": r["seconds"]["setup"],
                     "run_model": r["seconds"]["run_model"], "compute_totals rev": r["seconds"]["compute_totals_rev"],
                     "cd": r["cruise.cd"][0]})
    for mode in ("fwd", "rev"):
        wf, kf = _worst(ffd["both"][f"check_totals_{mode}"])
        r = {"case": f"check_totals {mode}", "ffd worst": wf, "ffd block": kf}
        if pg:
            wp, kp = _worst(pg["both"][f"check_totals_{mode}"])
            r.update({"pyGeo worst": wp, "pyGeo block": kp})
        rows.append(r)
    if not pg:
        rows.append({"case": "pyGeo", "ffd cl": "skipped: no pyGeo environment with openmdao and mphys "
                                                "(FFD_PYGEO_PYTHON; ../shared/peers/README.md)"})
    return rows


def summary(rows: list[dict]) -> list[dict]:
    out = []
    for r in rows:
        if r["case"] in CASES and "pyGeo cd" in r:
            out.append({"case": f"{r['case']}: cd ffd / pyGeo", "measured": f"{r['ffd cd']:.6g} / {r['pyGeo cd']:.6g}",
                        "target": "", "pyGeo reference": f"surface diff {r['surface max diff / root chord']:.2e} c, "
                                                          f"incidence diff {r['incidence max diff (deg)']:.2e} deg"})
        elif r["case"].startswith("times (s), "):
            out.append({"case": r["case"], "measured": f"setup {r['setup']:.3g} s, run_model {r['run_model']:.3g} s, "
                                                       f"totals (rev) {r['compute_totals rev']:.3g} s",
                        "target": "", "pyGeo reference": ""})
        elif r["case"] == "times (s)":
            out.append({"case": "times, 1,200 points", "measured": f"setup {r['ffd setup']:.3g} s, run_model "
                        f"{r['ffd run_model']:.3g} s, totals (rev) {r['ffd compute_totals rev']:.3g} s", "target": "",
                        "pyGeo reference": f"{r.get('pyGeo setup', float('nan')):.3g} / "
                                           f"{r.get('pyGeo run_model', float('nan')):.3g} / "
                                           f"{r.get('pyGeo compute_totals rev', float('nan')):.3g} s"})
        elif r["case"].startswith("check_totals"):
            out.append({"case": r["case"], "measured": f"ffd {r['ffd worst']:.1e}", "target": "<= 1e-6",
                        "pyGeo reference": f"{r.get('pyGeo worst', float('nan')):.1e}", "met": r["ffd worst"] <= 1e-6})
    return out


if __name__ == "__main__":
    for r in run("--quick" in sys.argv):
        print(json.dumps(r))
