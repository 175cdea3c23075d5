"""The wall layer under MPI: what finding it on the ranks' local meshes costs, on the RANS meshes.

``mpiexec -n R python -m benchmarks.bench_wall_layer_mpi`` (R = 1, 2, 3; the ``[mpi]`` extra): for SU2's
RAE2822 RANS mesh (shared data, first cell 1e-5 chord), a NACA 0012 O-mesh with a 1e-6 chord first cell
(193 x 71) and the 32-layer prism wing (``gmsh_wings`` case ``rect_z_rans32``), each rank takes its local
mesh (:func:`ffdcli.parallel.partition.localize`) and finds the layer
(:func:`ffdcli.volume.wall_layer.detect_wall_layer` with the rank's
:class:`~ffdcli.parallel.distributed.RankNodes`: the owners' off-wall edges gathered, the stacks walked
one gather per layer). Printed per mesh: the nodes and wall nodes, the layers walked (gathers), the
bytes each rank received in those gathers (the arrays' payload, summed over the ranks' contributions),
the time of the detection (slowest rank, best of 3) and, at 1 rank, the serial detection on the whole
mesh; and whether every rank's layer is the serial one's rows bit for bit. Run from the repository
root: ``python -m benchmarks.bench_wall_layer_mpi [--ranks 1 2 3]`` (it launches mpiexec itself).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RAE2822 = Path("/work/shared/data/su2/deformation__rae2822__mesh_RAE2822_turb_ffd.su2")


class _Counting:
    """A communicator that counts the gathers and the bytes of the arrays it receives."""

    def __init__(self, comm):
        self.comm, self.rank, self.size = comm, comm.rank, comm.size
        self.calls, self.received = 0, 0

    def allgather(self, obj):
        got = self.comm.allgather(obj)
        self.calls += 1
        for g in got:
            for a in (g if isinstance(g, tuple) else (g,)):
                self.received += int(getattr(a, "nbytes", 0))
        return got


def _meshes(folder: Path) -> dict:
    from ffdcli.io.formats import write_mesh
    from ffdcli.testing import gmsh_wings
    from ffdcli.testing.ogrid import airfoil_ogrid_mesh

    out = {}
    if RAE2822.is_file():
        out["rae2822"] = (str(RAE2822), "AIRFOIL")
    write_mesh(airfoil_ogrid_mesh("0012", 193, 71, first_cell=1e-6), folder / "ogrid.su2")
    out["ogrid_1e-6"] = (str(folder / "ogrid.su2"), "airfoil")
    out["wing_rans32"] = (str(gmsh_wings.write_case("rect_z_rans32", folder)), "wing")
    return out


def _detect(mesh, surface: str, *, targets=None, nodes=None, size=None):
    """(the warp's model without its layer, the layer, seconds of the detection alone)."""
    from ffdcli.volume.wall_layer import detect_wall_layer
    from ffdcli.volume.warp import WarpSettings, prepare_mesh_warp

    model, roles = prepare_mesh_warp(mesh, surface, WarpSettings(wall_layer="none"), targets=targets, size=size)
    t0 = time.perf_counter()
    layer = detect_wall_layer(mesh.points, mesh.cells, mesh.marker_faces([surface]), model.surface_ids,
                              model.target_ids, roles.sliding, nodes)
    return model, layer, time.perf_counter() - t0


def _child(path: str, surface: str) -> dict:
    from ffdcli.io.formats import read_mesh
    from ffdcli.mesh import diagonal
    from ffdcli.parallel.comm import world
    from ffdcli.parallel.distributed import RankNodes
    from ffdcli.parallel.partition import localize, node_owners

    comm = world()
    mesh = read_mesh(path)
    serial, ser, t_serial = _detect(mesh, surface)
    local, part = localize(mesh, node_owners(mesh.points, comm.size), comm.rank)
    owned = np.zeros(len(local.points), dtype=bool)
    owned[part.rows[part.owned]] = True
    best, counted = np.inf, None
    for _ in range(3):
        counted = _Counting(comm)
        comm.barrier()
        model, lay, dt = _detect(local, surface, targets=part.rows, size=diagonal(mesh.points),
                                 nodes=RankNodes(counted, local.global_ids, owned))
        best = min(best, max(comm.allgather(dt)))
    gid = local.global_ids[model.target_ids[lay.rows]]
    where = {int(t): i for i, t in enumerate(serial.target_ids[ser.rows])}
    idx = np.array([where[int(t)] for t in gid], dtype=np.int64)
    same = (np.array_equal(lay.weight, ser.weight[idx]) and np.array_equal(lay.position, ser.position[idx])
            and (lay.partition != ser.partition[idx]).nnz == 0 and lay.thickness == ser.thickness
            and np.array_equal(lay.normals, ser.normals) and np.array_equal(lay.planes, ser.planes))
    return {"ranks": comm.size, "nodes": mesh.n_points, "wall_nodes": len(serial.surface_ids),
            "gathers": counted.calls, "received_bytes": max(comm.allgather(counted.received)),
            "seconds": round(best, 4), "serial_seconds": round(t_serial, 4),
            "same_as_serial": all(comm.allgather(bool(same))), "layer_rows": comm.allgather(len(lay.rows))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        out = _child(*args.child)
        from ffdcli.parallel.comm import world

        if world().is_root:
            print(json.dumps(out))
        return 0
    mpiexec = shutil.which("mpiexec", path=str(Path(sys.executable).parent)) or shutil.which("mpiexec")
    if mpiexec is None:
        print("the [mpi] extra is not installed")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        for name, (path, surface) in _meshes(Path(tmp)).items():
            for r in args.ranks:
                proc = subprocess.run([mpiexec, "-n", str(r), sys.executable, "-m", "benchmarks.bench_wall_layer_mpi",
                                       "--child", path, surface], capture_output=True, text=True)
                line = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
                if proc.returncode or not line:
                    print(name, r, "failed:", proc.stderr[-800:])
                    continue
                print(name, line[-1])
    return 0


if __name__ == "__main__":
    sys.exit(main())
