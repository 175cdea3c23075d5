"""``python -m ffdcli.app.warmup``: compile ffd's numba kernels once, ahead of the first run.

numba compiles a kernel at its first call and keeps it on disk (``cache=True``, in ``__pycache__``
beside the sources or in ``NUMBA_CACHE_DIR``); a fresh install would otherwise pause at its first
``ffd box`` or ``ffd deform`` (a minute or two). ``make demo`` and ``make test`` run this once after
installing, with one line per step; after it, the first run of a command costs what a later one does
whatever the lattice degrees (the usual degrees have kernels of their own, compiled here; every
other combination runs the generic kernels, compiled here once for all of them).

Steps: the lattice kernels (embedding, ``B @ P``, ``B.T @ g``, the basis matrix, the Jacobian
product) for every degree combination of :data:`ffdcli.lattice._newton_kernels.SPECIALISED` and for
the generic ones; then, in a source checkout (``samples/`` and ``configs/`` beside the package), a 3D
and a 2D design end to end (box fit, changes, volume motion, quality gate, SU2 read and write) into
a temporary folder, which compiles the volume, gate and I/O kernels; and the wall layer of a small
RANS mesh (a flat plate's quads grown from a 1e-6 first cell), which compiles the stack walk's
kernels (:mod:`ffdcli.volume._stack_walk`; the bundled designs' meshes have no boundary layer). The
steps run side by side,
one worker process per core (:mod:`ffdcli.app.processes`; ``-j 1``: one after the other).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ffdcli.app.pipeline import deform, load_run, write_outputs
from ffdcli.app.processes import default_jobs, run_steps
from ffdcli.design import load_design
from ffdcli.jit import cache_dir
from ffdcli.lattice._newton_kernels import SPECIALISED
from ffdcli.lattice.embedding import embed
from ffdcli.lattice.lattice import Lattice
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.parameterization.derivatives import csr_times_dense
from ffdcli.progress import no_progress
from ffdcli.volume.warp import prepare_mesh_warp, warp

REPO = Path(__file__).resolve().parents[2]
#: Degrees (three-axis form) that run the generic kernels: compiling one compiles them for every
#: combination outside :data:`~ffdcli.lattice._newton_kernels.SPECIALISED`.
GENERIC = (2, 2, 2)
#: Design files of a source checkout run end to end (3D and 2D).
DESIGNS = ("rect_twist_linear.yaml", "naca0012_s1223.yaml")


def sample_lattice(degrees: tuple[int, int, int]) -> Lattice:
    """A sheared, non-affine lattice with the three-axis ``degrees`` (third 0: a 2D lattice, 2 coordinates)."""
    pdim = 2 if degrees[2] == 0 else 3
    deg = degrees[:pdim]
    shape = tuple(p + 2 for p in deg)
    grids = np.meshgrid(*(np.linspace(0.0, 1.0, n) for n in shape), indexing="ij")
    cp = np.stack(grids, axis=-1)
    cp[..., 0] += 0.2 * cp[..., 1] + 0.05 * cp[..., 1] ** 2
    return Lattice(cp, deg)


def lattice_kernels(degrees: tuple[int, int, int]) -> None:
    """Run every lattice kernel once for ``degrees``: embed, ``B @ P`` (displace, evaluate),
    ``B.T @ g`` (gdim 1 to 3), the CSR basis and the Jacobian product."""
    lat = sample_lattice(degrees)
    rng = np.random.default_rng(0)
    pts = rng.uniform(0.05, 0.95, (64, lat.gdim))
    emb = embed(lat, pts)
    emb.displace(np.zeros(lat.control_points.shape))
    emb.evaluate(lat.control_points)
    for gdim in range(1, lat.gdim + 1):
        emb.rmatvec(np.ones((emb.n_points, gdim)))
    B = emb.basis_matrix()
    csr_times_dense(B, np.ones((lat.n_ctrl, 2)))


def run_design(config: Path, out: Path) -> None:
    """One design end to end into ``out`` (no box cache read or written)."""
    design = load_design(config)
    run = load_run(design, use_cache=False, progress=no_progress)
    result = deform(run, progress=no_progress)
    write_outputs(run, result, mesh_path=out / f"{config.stem}{design.mesh.suffix}",
                  lattice_path=out / f"{config.stem}_lattice.vtk")


def layered_plate(n_x: int = 21, n_y: int = 25, first: float = 1e-6, growth: float = 1.6) -> Mesh:
    """A 2D quad mesh over a flat plate (marker ``wall`` at y = 0, ``far`` round the rest) whose cells
    grow from ``first`` off the wall by ``growth``: a RANS mesh's layer, in a few hundred nodes."""
    x = np.linspace(0.0, 1.0, n_x)
    y = np.r_[0.0, first * np.cumsum(growth ** np.arange(n_y - 1))]
    pts = np.zeros((n_x * n_y, 3))
    pts[:, 0], pts[:, 1] = np.repeat(x, n_y), np.tile(y, n_x)
    ids = np.arange(n_x * n_y).reshape(n_x, n_y)
    quads = np.stack([ids[:-1, :-1], ids[1:, :-1], ids[1:, 1:], ids[:-1, 1:]], axis=-1).reshape(-1, 4)
    far = np.concatenate([np.stack([ids[-1, :-1], ids[-1, 1:]], 1), np.stack([ids[1:, -1], ids[:-1, -1]], 1),
                          np.stack([ids[0, 1:], ids[0, :-1]], 1)])
    return Mesh(points=pts, dim=2, cells=[CellBlock("quad", quads)],
                markers={"wall": [CellBlock("line", np.stack([ids[:-1, 0], ids[1:, 0]], 1))],
                         "far": [CellBlock("line", far)]})


def wall_layer_kernels() -> None:
    """Find the wall layer of :func:`layered_plate` and move it (the stack walk's kernels)."""
    model, _ = prepare_mesh_warp(layered_plate(), "wall")
    if model.layer is None:
        raise RuntimeError("the warm-up plate has no wall layer")
    warp(model, np.full((model.n_surface, 3), 1e-3) * [0.0, 1.0, 0.0])


def run_step(kind: str, arg) -> float:
    """One warm-up step (``kind`` "lattice": degrees; "layer": the wall layer's; "design": a design file);
    its seconds."""
    t0 = time.perf_counter()
    if kind == "lattice":
        lattice_kernels(arg)
    elif kind == "layer":
        wall_layer_kernels()
    else:
        with tempfile.TemporaryDirectory(prefix="ffd-warmup-") as tmp:
            run_design(Path(arg), Path(tmp))
    return time.perf_counter() - t0


def steps(repo: Path = REPO) -> list[tuple[str, str, object]]:
    """(what, kind, argument) of every step (:func:`run_step`), the longest first."""
    out = []
    configs = [repo / "configs" / name for name in DESIGNS]
    if all(c.is_file() for c in configs):
        out += [(f"end to end: {c.name} (box, volume, quality gate, I/O)", "design", str(c)) for c in configs]
    out.append(("wall layer kernels (a RANS mesh's stacks of thin cells)", "layer", None))
    out += [(f"lattice kernels, degrees {d}", "lattice", d) for d in sorted(SPECIALISED)]
    out.append(("lattice kernels, every other degree combination (generic)", "lattice", GENERIC))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ffdcli.app.warmup", description=__doc__.splitlines()[0])
    ap.add_argument("-q", "--quiet", action="store_true", help="print nothing")
    ap.add_argument("-j", "--jobs", type=int, default=None,
                    help="worker processes (default: one per core, at most one per step; 1: in this process)")
    args = ap.parse_args(argv)
    say = (lambda text: None) if args.quiet else (lambda text: print(text, file=sys.stderr, flush=True))
    todo = steps()
    jobs = args.jobs or default_jobs(len(todo))
    say(f"ffd warmup: compiling the numba kernels once into {cache_dir()} ({len(todo)} steps, {jobs} at a "
        f"time; a step already compiled takes a second)")
    t_all = time.perf_counter()
    for k, (i, seconds) in enumerate(run_steps(run_step, [(kind, arg) for _, kind, arg in todo], jobs), 1):
        say(f"ffd warmup: [{k}/{len(todo)}] {todo[i][0]}: {seconds:.1f} s")
    say(f"ffd warmup: done in {time.perf_counter() - t_all:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
