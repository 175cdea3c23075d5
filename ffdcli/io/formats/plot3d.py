"""Multi-block ASCII Plot3D lattices, the format of pyGeo/DAFoam FFD files (``.xyz``).

Layout: the number of blocks; one line ``ni nj nk`` per block; then for each block all x values,
all y values, all z values, each with i varying fastest (Fortran order). Numbers may be spread
over any number of lines.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.io.atomic import atomic_write
from ffdcli.io.inputs import check_input_file


def read_plot3d(path) -> list[np.ndarray]:
    """Blocks of a multi-block ASCII Plot3D file, each (ni, nj, nk, 3)."""
    check_input_file(path, "Plot3D file")
    try:
        text = Path(path).read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read the Plot3D file: {e}", path=path) from None
    try:
        vals = np.array(text.replace("D", "E").replace("d", "e").split(), dtype=np.float64)
    except ValueError:
        raise InputError("not an ASCII Plot3D file (non-numeric values)", path=path) from None
    if len(vals) < 4 or vals[0] != int(vals[0]) or vals[0] < 1:
        raise InputError("not a Plot3D file: the first number must be the number of blocks", path=path)
    nb = int(vals[0])
    if len(vals) < 1 + 3 * nb:
        raise InputError(f"truncated Plot3D header ({nb} blocks announced)", path=path)
    dims = vals[1:1 + 3 * nb].reshape(nb, 3)
    if np.any(dims != np.round(dims)) or np.any(dims < 1):
        raise InputError("not a Plot3D file: block dimensions must be positive integers", path=path)
    dims = dims.astype(int)
    pos = 1 + 3 * nb
    need = pos + 3 * int(np.prod(dims, axis=1).sum())
    if len(vals) != need:
        raise InputError(f"expected {need - pos} coordinates for blocks {dims.tolist()}, found "
                         f"{len(vals) - pos}", path=path)
    blocks = []
    for ni, nj, nk in dims:
        cnt = ni * nj * nk
        xyz = vals[pos:pos + 3 * cnt].reshape(3, nk, nj, ni)       # Fortran: i fastest
        pos += 3 * cnt
        blocks.append(np.ascontiguousarray(xyz.transpose(3, 2, 1, 0)))
    if not all(np.all(np.isfinite(b)) for b in blocks):
        raise InputError("the Plot3D file has non-finite coordinates", path=path)
    return blocks


def write_plot3d(path, blocks: list[np.ndarray]) -> None:
    """Write blocks (each (ni, nj, nk, 3)) as multi-block ASCII Plot3D, atomically."""
    lines = [str(len(blocks))]
    lines += [" ".join(str(d) for d in b.shape[:3]) for b in blocks]
    body = []
    for b in blocks:
        for c in range(3):
            body.append(np.asarray(b[..., c]).transpose(2, 1, 0).ravel())
    with atomic_write(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")
        for arr in body:
            fh.write("\n".join(f"{v:.16e}" for v in arr.tolist()) + "\n")
