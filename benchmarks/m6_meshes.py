"""The ONERA M6 meshes of docs/optimize.md's mesh study, from the shared generator with three of its
constants changed.

``python -m benchmarks.m6_meshes H OUT.su2 [--far 50] [--growth 4] [--hmax 8000]``

The shared generator (``../shared/data/oneram6/gen_oneram6_step.py``; gmsh from the ``[samples]``
extra) has the wing's surface size ``H`` (mm) as its argument and fixes the far field at ten root
chords, the size's growth away from the wing at ``distance / 4`` and the largest size at 2.5 m. This
runs a copy of it with those three as options (``--far`` in root chords, ``--growth`` the divisor,
``--hmax`` in mm); the copy is written beside the output and deleted. Then run SU2 on it with
``configs/onera_m6_euler.cfg``'s settings (``MESH_FILENAME`` changed) to read its baseline drag.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

GENERATOR = Path(__file__).resolve().parents[2] / "shared" / "data" / "oneram6" / "gen_oneram6_step.py"


def generator_source(far: float, growth: float, hmax: float, geometry: Path) -> str:
    """The generator's text with the far field, the growth, the largest size and the STEP path set."""
    src = GENERATOR.read_text()
    subs = [
        (r"^R = 10 \* 805\.9.*$", f"R = {far!r} * 805.9"),
        (r"F\{f1\}/4 \+", f"F{{f1}}/{growth!r} +"),
        (r'"Mesh\.MeshSizeMax": 2500\.0', f'"Mesh.MeshSizeMax": {hmax!r}'),
        (r'os\.path\.join\(os\.path\.dirname\(os\.path\.abspath\(__file__\)\), "\.\.", "geometry", '
         r'"onera_m6_sharp_te\.stp"\)', repr(str(geometry))),
    ]
    for pattern, value in subs:
        src, n = re.subn(pattern, lambda m, v=value: v, src, flags=re.M)
        if n != 1:
            raise SystemExit(f"{GENERATOR}: the constant {pattern!r} is not there once (found {n}): "
                             "the generator changed; update benchmarks/m6_meshes.py")
    return src


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.m6_meshes", description=__doc__.splitlines()[0])
    ap.add_argument("h", type=float, help="the wing's surface size, mm (the generator's argument)")
    ap.add_argument("out", help="the .su2 mesh to write")
    ap.add_argument("--far", type=float, default=10.0, help="far field, root chords (generator: 10)")
    ap.add_argument("--growth", type=float, default=4.0, help="size = h + distance / growth (generator: 4)")
    ap.add_argument("--hmax", type=float, default=2500.0, help="largest size, mm (generator: 2500)")
    args = ap.parse_args(argv)
    if not GENERATOR.is_file():
        print(f"error: the generator is not at {GENERATOR}", file=sys.stderr)
        return 2
    geometry = GENERATOR.parents[1] / "geometry" / "onera_m6_sharp_te.stp"
    src = generator_source(args.far, args.growth, args.hmax, geometry)
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "gen.py"
        script.write_text(src)
        return subprocess.call([sys.executable, str(script), repr(args.h), str(Path(args.out).resolve())])


if __name__ == "__main__":
    sys.exit(main())
