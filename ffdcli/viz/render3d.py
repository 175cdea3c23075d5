"""An optional 3D picture of a design (pyvista, off-screen), rendered in a subprocess.

VTK segfaults instead of raising when no OpenGL backend exists (TOOLING.md), so the rendering runs
in a child process: if pyvista is missing, no backend works, or the child fails, :func:`render_3d`
returns None and the caller keeps its matplotlib views. Needs ``pip install ffdcli[viz]`` (pyvista);
headless machines use VTK's EGL window on Mesa (``libegl1``, ``libgl1-mesa-dri``).
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from ffdcli.io.atomic import atomic_write

TIMEOUT = 180
#: Camera direction from the wing's centre in (chord, thickness, span) units: ahead, above and
#: outboard, so that the section loops (black original, red deformed) line up towards the tip.
VIEW = (-0.5, 0.5, 0.7)


def pyvista_available() -> bool:
    return importlib.util.find_spec("pyvista") is not None


def render_3d(X0: np.ndarray, X1: np.ndarray, faces: list, P0: np.ndarray, P1: np.ndarray, path,
              *, title: str = "", axes=None, lines0=(), lines1=()) -> Path | None:
    """Write a 3D PNG to ``path``; None if impossible.

    The original surface is grey and translucent with its section loops ``lines0`` (list of (K, 3))
    in black, the deformed one red with ``lines1`` in dark red, the deformed lattice dark red; an
    axis triad (x, y, z) and the bounds with tick labels give the orientation and the scale."""
    if not pyvista_available():
        return None
    path = Path(path)
    tris = [f.data for f in faces if f.type == "triangle"]
    quads = [f.data for f in faces if f.type == "quad"]
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "scene.npz"
        np.savez(data, X0=X0, X1=X1, tris=np.concatenate(tris) if tris else np.zeros((0, 3), int),
                 quads=np.concatenate(quads) if quads else np.zeros((0, 4), int), P0=P0, P1=P1,
                 title=np.array(title), axes=np.asarray(axes if axes is not None else np.eye(3)),
                 **_polylines("lines0", lines0), **_polylines("lines1", lines1))
        out = Path(tmp) / "view.png"
        env = dict(os.environ, VTK_DEFAULT_OPENGL_WINDOW="vtkEGLRenderWindow", PYVISTA_OFF_SCREEN="true")
        try:
            proc = subprocess.run([sys.executable, "-m", "ffdcli.viz.render3d", str(data), str(out)], env=env,
                                  capture_output=True, timeout=TIMEOUT)
        except (OSError, subprocess.TimeoutExpired):
            return None
        if proc.returncode != 0 or not out.exists() or out.stat().st_size == 0:
            return None

        with atomic_write(path) as fh:
            fh.write(out.read_bytes())
    return path


def _polylines(key: str, lines) -> dict:
    """Polylines as two arrays for np.savez: stacked points and the length of each line."""
    lines = [np.asarray(q, dtype=np.float64) for q in lines]
    pts = np.concatenate(lines) if lines else np.zeros((0, 3))
    return {key: pts, key + "_n": np.array([len(q) for q in lines], dtype=np.int64)}


def _polydata_lines(pv, pts: np.ndarray, counts: np.ndarray):
    cells, start = [], 0
    for k in counts:
        cells.append(np.r_[k, np.arange(start, start + k)])
        start += k
    return pv.PolyData(pts, lines=np.concatenate(cells)) if cells else None


def _corner(lo: np.ndarray, hi: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The corner of the bounds at the leading edge (low chord) and the root (low span) side."""
    out = lo.copy()
    for v in (c, s):
        k = int(np.argmax(np.abs(v)))
        out[k] = lo[k] if v[k] > 0 else hi[k]
    return out


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
    import pyvista as pv  # noqa: PLC0415 (the [viz] extra)

    z = np.load(data)
    faces = []
    for key, k in (("tris", 3), ("quads", 4)):
        f = z[key]
        if len(f):
            faces.append(np.c_[np.full(len(f), k), f].ravel())
    cells = np.concatenate(faces) if faces else np.zeros(0, int)
    p = pv.Plotter(off_screen=True, window_size=(1400, 950))
    p.set_background("white")
    p.add_mesh(pv.PolyData(z["X1"], cells), color="#d62728", smooth_shading=True, opacity=0.55)
    p.add_mesh(pv.PolyData(z["X0"], cells), color="#8c8c8c", opacity=0.45)
    for key, color, width in (("lines0", "black", 2.5), ("lines1", "#7f0000", 2.0)):
        if key in z.files and len(z[key]):
            poly = _polydata_lines(pv, z[key], z[key + "_n"])
            if poly is not None:
                p.add_mesh(poly, color=color, line_width=width)
    P1 = z["P1"].reshape(-1, 3)
    segs = _lattice_lines(z["P1"])
    lines = np.c_[np.full(len(segs), 2), segs].ravel()
    p.add_mesh(pv.PolyData(P1, lines=lines), color="#7f0000", line_width=1.0, opacity=0.6)
    p.add_points(P1, color="#7f0000", point_size=6, render_points_as_spheres=True)
    title = str(z["title"])
    if title:
        p.add_text(title, font_size=10, color="black")
    c, t, s = z["axes"]                       # chord, thickness ("up"), span unit vectors
    W = np.concatenate([z["X0"], z["X1"]])
    lo, hi = W.min(0), W.max(0)
    size = float(np.linalg.norm(hi - lo))
    # the scale: the wing's bounds with tick labels (before the triad, which would widen them)
    p.show_bounds(bounds=[lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]], grid=False, location="outer",
                  color="black", font_size=9, xtitle="x", ytitle="y", ztitle="z", fmt="%.3g")
    # the axis triad: arrows along +x, +y, +z ahead of the root's leading edge, labelled
    origin = _corner(lo, hi, c, s) - 0.06 * size * c
    L = 0.07 * size
    for k, name in enumerate("xyz"):
        e = np.zeros(3)
        e[k] = 1.0
        p.add_mesh(pv.Arrow(start=origin, direction=e, scale=L, tip_length=0.25, tip_radius=0.08,
                            shaft_radius=0.03), color=("#1f77b4", "#2ca02c", "#ff7f0e")[k])
        p.add_point_labels(np.array([origin + 1.2 * L * e]), [name], font_size=16, text_color="black",
                           shape=None, show_points=False, always_visible=True)
    focal = 0.5 * (lo + hi)
    d = np.asarray(VIEW[0] * c + VIEW[1] * t + VIEW[2] * s, dtype=np.float64)
    d /= np.linalg.norm(d)
    p.camera_position = [tuple(focal + 3.0 * size * d), tuple(focal), tuple(t)]
    p.reset_camera(bounds=[lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]])   # the whole wing, root too
    p.camera.zoom(1.15)
    p.screenshot(out)
    p.close()


if __name__ == "__main__":
    if len(sys.argv) > 3:                      # a camera direction to try: chord,thickness,span
        VIEW = tuple(float(v) for v in sys.argv[3].split(","))
    _main(sys.argv[1], sys.argv[2])
