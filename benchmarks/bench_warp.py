"""Volume-mesh warp (``ffdcli.volume.warp``): time, peak memory and tree error on a synthetic wing mesh.

The mesh: a half wing (elliptic sections, chord 1 at the root, taper 0.5, span 3, 12 % thick; see
:func:`wing_surface`) sampled on a parametric grid of ``n_surface`` nodes, and volume nodes
extruded along the surface normals in layers of geometric growth (first layer 1e-4 chord, ratio
1.5: clustered at the wall like a RANS mesh), plus a fixed farfield sphere (radius 60, 4000 nodes). The motion
is a linear twist to 10 degrees at the tip about the trailing-edge line with the rotation of each
surface node's frame, i.e. the use case of `ffd deform`.

Columns: ``volume_nodes`` (targets), ``surface_nodes``, ``prepare_s`` (tree build),
``warp_first_s`` (the first warp with rotations on the model, after a warm-up call on another model
that compiles/loads the kernels: it includes each target's reference weight, which the model then
keeps; what one ``ffd deform`` pays), ``warp_s`` (the smallest of ``repeats`` calls, the first
included; ``warp_max_s`` the largest), ``warp_cpu_s`` (CPU seconds of the
fastest call over all threads: warp_s on an idle machine is about warp_cpu_s / cores), ``load``
(the 1-minute load average before and after: the machine is shared),
``peak_mb`` (peak RSS, VmHWM, of the child process that did everything), ``err_max`` (max |tree - exact|
over a subset of ``err_subset`` volume nodes, relative to the max surface displacement; the exact
O(N x Ns) sum is evaluated on that subset only), and the targets.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

TITLE = "Volume-mesh warp (IDW with rotations, tree approximation)"
NOTES = ("Targets: 1M volume nodes and 50k surface nodes in <= 8 s and <= 2 GB with the "
         "default volume settings; err_max <= 1e-3 (x max surface displacement). The row 'old defaults' "
         "(alpha 0.25, no rotation fade) is measured in the same run for the ratio. peak_mb = peak RSS "
         "(VmHWM) of a child process that also built the mesh; the machine has 2 cores shared with other work.")

SPAN, THICK, TAPER = 3.0, 0.12, 0.5


def wing_surface(n_surface: int):
    """Points, unit normals and vertex areas of a half wing, about ``n_surface`` nodes.

    Elliptic sections (chord c(y) = 1 - TAPER y / SPAN, thickness THICK c), trailing edge at
    x = 0.5 c, span y in [0, SPAN] (the root y = 0 is a symmetry plane); nodes clustered towards
    the leading and trailing edges (cosine spacing around the section) and the tip.
    """
    nv = int(round(np.sqrt(n_surface / 2.5)))
    nu = n_surface // nv
    u = np.pi * (1 - np.cos(2 * np.pi * np.arange(nu) / nu)) / 2       # clustered at 0 and pi
    u = np.where(np.arange(nu) < nu / 2, u, 2 * np.pi - u)
    v = SPAN * np.sin(0.5 * np.pi * np.arange(nv) / (nv - 1))          # clustered at the tip
    U, V = np.meshgrid(u, v, indexing="ij")
    c = 1 - TAPER * V / SPAN
    dc = -TAPER / SPAN
    p = np.stack([0.5 * c * np.cos(U), V, 0.5 * THICK * c * np.sin(U)], axis=-1).reshape(-1, 3)
    pu = np.stack([-0.5 * c * np.sin(U), 0 * U, 0.5 * THICK * c * np.cos(U)], -1).reshape(-1, 3)
    pv = np.stack([0.5 * dc * np.cos(U), 1 + 0 * U, 0.5 * THICK * dc * np.sin(U)], -1).reshape(-1, 3)
    n = np.cross(pv, pu)
    jac = np.linalg.norm(n, axis=1)
    n /= jac[:, None]
    du = np.gradient(np.unwrap(np.concatenate([u, u[:1] + 2 * np.pi])))[:-1]
    dv = np.gradient(v)
    area = jac * (du[:, None] * dv[None, :]).ravel()
    return p, n, area


def synthetic_mesh(n_volume: int, n_surface: int, n_far: int = 4000, seed: int = 0):
    """(points, surface ids, fixed ids, areas): surface first, then farfield, then volume nodes."""
    p, n, area = wing_surface(n_surface)
    ns = len(p)
    layers = int(np.ceil(n_volume / ns))
    h = 1e-4 * (1.5 ** np.arange(layers + 1) - 1) / 0.5              # distance of layer k from the wall
    h = h[1:]
    rng = np.random.default_rng(seed)
    vol = (p[None, :, :] + h[:, None, None] * n[None, :, :]).reshape(-1, 3)[:n_volume]
    vol += rng.normal(scale=1e-6, size=vol.shape) * (1 + np.linalg.norm(vol, axis=1))[:, None]
    far = rng.normal(size=(n_far, 3))
    far = 60.0 * far / np.linalg.norm(far, axis=1)[:, None]
    pts = np.vstack([p, far, vol])
    areas = np.zeros(len(pts))
    areas[:ns] = area
    areas[ns:ns + n_far] = 4 * np.pi * 60.0**2 / n_far
    return pts, np.arange(ns), np.arange(ns, ns + n_far), areas


def twist_motion(x: np.ndarray, tip_deg: float = 10.0):
    """Linear twist about the line x = 0.5, z = 0 (span axis y): (b (Ns, 3), R (Ns, 3, 3))."""
    th = np.radians(tip_deg) * np.abs(x[:, 1]) / SPAN
    c, s = np.cos(th), np.sin(th)
    R = np.zeros((len(x), 3, 3))
    R[:, 0, 0] = c
    R[:, 0, 2] = s
    R[:, 1, 1] = 1
    R[:, 2, 0] = -s
    R[:, 2, 2] = c
    rel = x - np.array([0.5, 0.0, 0.0])
    rel[:, 1] = 0
    b = np.einsum("nij,nj->ni", R, rel) - rel
    return b, R


def measure(n_volume: int, n_surface: int, n_subset: int, tolerance: float = 1e-3,
            old: bool = False, repeats: int = 3) -> dict:
    """Everything in this process (run it in a child for a clean peak memory). ``old``: the
    old defaults (alpha 0.25, no rotation fade), for the speed ratio."""
    from ffdcli.volume.warp import WarpSettings, prepare_warp, warp

    pts, sid, fid, areas = synthetic_mesh(n_volume, n_surface)
    settings = WarpSettings(tolerance=tolerance)
    if old:
        settings = WarpSettings(tolerance=tolerance, alpha=0.25, rotation_reach=None)
    b, R = twist_motion(pts[sid])
    # warm-up on a small problem: loads the cached kernels (or compiles them once)
    small = prepare_warp(pts[: len(sid) + len(fid) + 1000], sid, fid, settings=settings,
                         areas=areas[: len(sid) + len(fid) + 1000])
    warp(small, b, R)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    model = prepare_warp(pts, sid, fid, settings=settings, areas=areas)
    t1 = time.perf_counter()
    walls, cpus = [], []
    for _ in range(repeats):
        c1 = _cpu()
        w0 = time.perf_counter()
        d = warp(model, b, R)
        walls.append(time.perf_counter() - w0)
        cpus.append(_cpu() - c1)
    load1 = os.getloadavg()[0]
    rng = np.random.default_rng(1)
    first = len(sid) + len(fid)
    sub = first + rng.choice(len(pts) - first, size=min(n_subset, len(pts) - first), replace=False)
    keep = np.concatenate([sid, fid, sub])
    sub_model = prepare_warp(pts[keep], np.arange(len(sid)), np.arange(len(sid), first),
                             settings=settings, areas=areas[keep])
    assert np.allclose(sub_model.origin, model.origin) and sub_model.ldef == model.ldef
    t3 = time.perf_counter()
    exact = warp(sub_model, b, R, exact=True)[first:]
    t4 = time.perf_counter()
    bmax = float(np.linalg.norm(b, axis=1).max())
    err = float(np.linalg.norm(d[sub] - exact, axis=1).max() / bmax)
    # VmHWM: this process's own peak (ru_maxrss would include the parent's peak, inherited at exec)
    peak = int(next(ln for ln in open("/proc/self/status") if ln.startswith("VmHWM:")).split()[1]) / 1024
    return {"volume_nodes": model.n_targets, "surface_nodes": model.n_surface,
            "prepare_s": t1 - t0, "warp_first_s": walls[0], "warp_s": min(walls), "warp_max_s": max(walls),
            "warp_cpu_s": cpus[int(np.argmin(walls))], "repeats": repeats, "load": [load0, load1],
            "peak_mb": peak, "err_subset": len(sub),
            "err_max": err, "exact_subset_s": t4 - t3, "tolerance": tolerance,
            "max_disp": bmax}


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _child(n_volume: int, n_surface: int, n_subset: int, old: bool = False) -> dict:
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, "-m", "benchmarks.bench_warp", "--child", str(n_volume),
                           str(n_surface), str(n_subset)] + (["--old"] if old else []), cwd=root,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"bench_warp child failed: {proc.stderr.strip().splitlines()[-1:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run(quick: bool = False) -> list[dict]:
    """Benchmark rows for ``python -m benchmarks``: 100k volume nodes when ``quick``, else 1M."""
    n_volume = 100_000 if quick else 1_000_000
    n_subset = 10_000 if quick else 100_000
    rows = []
    for old in ((False,) if quick else (False, True)):
        r = _child(n_volume, 50_000, n_subset, old)
        total = r["prepare_s"] + r.get("warp_first_s", r["warp_s"])
        row = {"name": f"warp_{n_volume // 1000}k_{r['surface_nodes'] // 1000}k" + ("_old" if old else ""),
               **r, "total_s": total, "old_defaults": old}
        if not quick and not old:
            row["ok"] = total <= 8 and r["peak_mb"] <= 2048 and r["err_max"] <= 1e-3
        rows.append(row)
    return rows


def summary(rows: list[dict]) -> list[dict]:
    """The rows in the runner's columns: case / measured / target / pyGeo reference / met."""
    return [{"case": f"warp {r['volume_nodes'] / 1e6:.2f}M volume / {r['surface_nodes'] / 1e3:.0f}k surface "
                     "nodes (synthetic layers)" + (", old defaults" if r.get("old_defaults") else ""),
             "measured": f"{r['total_s']:.1f} s ({r['prepare_s']:.1f} prepare + {r['warp_first_s']:.1f} first warp; "
                         f"min / max of {r['repeats']} {r['warp_s']:.1f} / {r['warp_max_s']:.1f} s, "
                         f"{r['warp_cpu_s']:.1f} CPU s), "
                         f"{r['peak_mb']:.0f} MB, err {r['err_max']:.1e}; load "
                         f"{r['load'][0]:.1f}-{r['load'][1]:.1f} on {os.cpu_count()} cores",
             "target": "<= 8 s, <= 2 GB, err <= 1e-3" if "ok" in r else "",
             "pyGeo reference": "", "met": r.get("ok")} for r in rows]


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        nv, ns, nsub = (int(a) for a in sys.argv[2:5])
        print(json.dumps(measure(nv, ns, nsub, old="--old" in sys.argv)))
    else:
        quick = "--quick" in sys.argv
        for row in run(quick):
            print(json.dumps(row))
