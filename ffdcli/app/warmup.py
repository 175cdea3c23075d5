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
a temporary folder, which compiles the volume, gate and I/O kernels. The steps run side by side,
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
from ffdcli.parameterization.derivatives import csr_times_dense
from ffdcli.progress import no_progress

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


def run_step(kind: str, arg) -> float:
    """One warm-up step (``kind`` "lattice": degrees; "design": a design file); its seconds."""
    t0 = time.perf_counter()
    if kind == "lattice":
        lattice_kernels(arg)
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
