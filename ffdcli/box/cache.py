"""The box and embedding cache: one ``.npz`` file beside the mesh (or in ``--cache-dir``).

Embedding a big surface is the expensive part of FFD; ``ffd deform`` runs in a loop over designs
reuse it. The file name carries the key (``<mesh name>.<key>.ffdcache.npz``) and the key is the
SHA-256 of the mesh file's bytes, the surface marker names, the box settings, the tool version and
the cache format. A file whose stored key differs, that cannot be read, or whose arrays do not fit
together is stale or corrupt: it is rebuilt (and replaced atomically), never used. Two processes
building the same cache at once each write a complete file and rename it into place; the last
rename wins and both files were valid.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from ffdcli import __version__
from ffdcli.box.box import Box
from ffdcli.errors import InputError
from ffdcli.io.inputs import polymesh_folder_of
from ffdcli.io.keyed_npz import read_keyed, write_keyed
from ffdcli.lattice.embedding import Embedding
from ffdcli.settings import BoxSettings

#: Bumped whenever the content of the cache changes meaning.
CACHE_FORMAT = 2


def file_hash(path: str | Path, chunk: int = 1 << 22) -> str:
    """SHA-256 of a file's bytes (hex). Of an OpenFOAM case folder: of its polyMesh's files (each
    name, then its bytes, in name order)."""
    h = hashlib.sha256()
    folder = polymesh_folder_of(path) if Path(path).is_dir() else None
    files = [Path(path)] if folder is None else sorted(p for p in folder.iterdir() if p.is_file())
    for f in files:
        if folder is not None:
            h.update(f.name.encode() + b"\0")
        with open(f, "rb") as fh:
            while True:
                b = fh.read(chunk)
                if not b:
                    break
                h.update(b)
    return h.hexdigest()


def cache_key(mesh_hash: str, surface: list[str], settings: BoxSettings, extra: str = "") -> str:
    """The key of a box: mesh content, surface names, box settings, tool version, cache format."""
    blob = json.dumps({"mesh": mesh_hash, "surface": list(surface), "settings": settings.get_cache_key(),
                       "version": __version__, "format": CACHE_FORMAT, "extra": extra}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


def cache_path(mesh_path: str | Path, key: str, cache_dir: str | Path | None = None) -> Path:
    """Where the cache of ``mesh_path`` with ``key`` lives."""
    mp = Path(mesh_path)
    folder = Path(cache_dir) if cache_dir else mp.parent
    return folder / f"{mp.name}.{key[:16]}.ffdcache.npz"


def save(path: str | Path, key: str, box: Box, surface_ids: np.ndarray, embedding, report: dict,
         meta: dict | None = None) -> None:
    """Write the cache file atomically."""
    arrays = {
        **box.to_arrays(),                 # the box says how it is stored; its names are not the ones below
        "surface_ids": np.asarray(surface_ids, dtype=np.int64),
        "params": embedding.params,
        "inside": embedding.inside,
        "residual": embedding.residual,
    }
    write_keyed(path, key, CACHE_FORMAT, arrays, settings=box.settings.as_dict(), report=report, **(meta or {}))


def load(path: str | Path, key: str, settings: BoxSettings):
    """(box, surface_ids, embedding, header) from a cache file, or None if absent, stale or corrupt."""
    got = read_keyed(path, key, CACHE_FORMAT)
    if got is None:
        return None
    header, a = got
    if any(v.dtype.kind == "f" and not np.all(np.isfinite(v)) for v in a.values()):
        return None                  # a damaged file: no cache we write holds NaN or inf
    try:
        box = Box.from_arrays(a)            # its settings are in the key (and stored with it)
        nk = len(box.knots)
        ids = a["surface_ids"]
        params, inside, residual = a["params"], a["inside"].astype(bool), a["residual"]
        n_pts = len(ids)
        if params.shape != (n_pts, nk) or inside.shape != (n_pts,) or residual.shape != (n_pts,):
            return None
        if not (np.all(np.isfinite(params)) and params.min(initial=0) >= 0 and params.max(initial=0) <= 1):
            return None
        emb = Embedding.from_params(box.lattice(), params, inside=inside, residual=residual)
    except (KeyError, ValueError, TypeError, IndexError, InputError):    # arrays that do not fit together
        return None
    return box, ids, emb, header


def embedding_matches(box: Box, embedding, points: np.ndarray) -> bool:
    """Whether a cached embedding is the one of these surface ``points`` (S, 3) in this box.

    Checked on every load (one evaluation of B @ P, as cheap as one deformation): every point's
    stored residual against its re-evaluation ``|V(u) - X|``, inside points within the tolerance and
    outside points beyond it. A cache whose arrays were edited under a valid header (control points
    shifted, ``inside`` cleared, parameters moved) fails this and is rebuilt."""
    points = np.asarray(points, dtype=np.float64)
    if points.shape[0] != embedding.n_points:
        return False
    if not embedding.n_points:
        return True
    V = embedding.evaluate(box.core_control_points())
    r = np.linalg.norm(V - box.core_points(points), axis=1)
    size = box.lattice().size
    slack = 1e-12 * size                       # re-evaluation agrees to ~1e-16 of the size
    tol = embedding.tolerance
    ins = embedding.inside
    return bool(np.all(np.abs(r - embedding.residual) <= slack + 1e-9 * embedding.residual)
                and np.all(r[ins] <= tol + slack) and np.all(r[~ins] > tol - slack))
