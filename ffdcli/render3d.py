"""An optional 3D picture of a design (pyvista, off-screen), rendered in a subprocess.

VTK segfaults instead of raising when no OpenGL backend exists (TOOLING.md), so the rendering runs
in a child process: if pyvista is missing, no backend works, or the child fails, :func:`render_3d`
returns None and the caller keeps its matplotlib views. Needs ``pip install ffdcli[viz]`` (pyvista);
headless machines use VTK's EGL window on Mesa (``libegl1``, ``libgl1-mesa-dri``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

TIMEOUT = 180


def pyvista_available() -> bool:
    import importlib.util

    return importlib.util.find_spec("pyvista") is not None


def render_3d(X0: np.ndarray, X1: np.ndarray, faces: list, P0: np.ndarray, P1: np.ndarray, path,
              *, title: str = "", axes=None) -> Path | None:
    """Write a 3D PNG (original grey, deformed red, deformed lattice) to ``path``; None if impossible."""
    if not pyvista_available():
        return None
    path = Path(path)
    tris = [f.data for f in faces if f.type == "triangle"]
    quads = [f.data for f in faces if f.type == "quad"]
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "scene.npz"
        np.savez(data, X0=X0, X1=X1, tris=np.concatenate(tris) if tris else np.zeros((0, 3), int),
                 quads=np.concatenate(quads) if quads else np.zeros((0, 4), int), P0=P0, P1=P1,
                 title=np.array(title), axes=np.asarray(axes if axes is not None else np.eye(3)))
        out = Path(tmp) / "view.png"
        env = dict(os.environ, VTK_DEFAULT_OPENGL_WINDOW="vtkEGLRenderWindow", PYVISTA_OFF_SCREEN="true")
        try:
            proc = subprocess.run([sys.executable, "-m", "ffdcli.render3d", str(data), str(out)], env=env,
                                  capture_output=True, timeout=TIMEOUT)
        except (OSError, subprocess.TimeoutExpired):
            return None
        if proc.returncode != 0 or not out.exists() or out.stat().st_size == 0:
            return None
        from ffdcli.atomic import atomic_write

        with atomic_write(path) as fh:
            fh.write(out.read_bytes())
    return path


def _lattice_lines(P: np.ndarray):
    n, m, l, _ = P.shape
    idx = np.arange(n * m * l).reshape(n, m, l)
    segs = []
    for ax in range(3):
        a = np.take(idx, np.arange(idx.shape[ax] - 1), axis=ax).ravel()
        b = np.take(idx, np.arange(1, idx.shape[ax]), axis=ax).ravel()
        segs.append(np.stack([a, b], 1))
    return np.concatenate(segs)


def _main(data: str, out: str) -> None:
    import pyvista as pv

    z = np.load(data)
    faces = []
    for key, k in (("tris", 3), ("quads", 4)):
        f = z[key]
        if len(f):
            faces.append(np.c_[np.full(len(f), k), f].ravel())
    cells = np.concatenate(faces) if faces else np.zeros(0, int)
    p = pv.Plotter(off_screen=True, window_size=(1200, 800))
    p.set_background("white")
    p.add_mesh(pv.PolyData(z["X0"], cells), color="lightgrey", opacity=0.5)
    p.add_mesh(pv.PolyData(z["X1"], cells), color="#d62728", smooth_shading=True)
    P1 = z["P1"].reshape(-1, 3)
    segs = _lattice_lines(z["P1"])
    lines = np.c_[np.full(len(segs), 2), segs].ravel()
    p.add_mesh(pv.PolyData(P1, lines=lines), color="#7f0000", line_width=1.5)
    p.add_points(P1, color="#7f0000", point_size=7, render_points_as_spheres=True)
    title = str(z["title"])
    if title:
        p.add_text(title, font_size=10, color="black")
    c, t, s = z["axes"]                       # chord, thickness ("up"), span unit vectors
    lo, hi = z["X1"].min(0), z["X1"].max(0)
    focal = 0.5 * (lo + hi)
    d = -0.55 * c + 0.75 * t - 0.65 * s       # from ahead, above and inboard of the root
    d /= np.linalg.norm(d)
    p.camera_position = [tuple(focal + 3.0 * np.linalg.norm(hi - lo) * d), tuple(focal), tuple(t)]
    p.reset_camera()
    p.camera.zoom(1.2)
    p.screenshot(out)
    p.close()


if __name__ == "__main__":
    _main(sys.argv[1], sys.argv[2])
