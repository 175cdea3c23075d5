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
import zipfile
from pathlib import Path

import numpy as np

from ffdcli import __version__
from ffdcli.axes import Axes
from ffdcli.box import Box
from ffdcli.errors import InputError
from ffdcli.settings import BoxSettings

#: Bumped whenever the content of the cache changes meaning.
CACHE_FORMAT = 1


def file_hash(path: str | Path, chunk: int = 1 << 22) -> str:
    """SHA-256 of a file's bytes (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
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
    from ffdcli.atomic import atomic_path

    header = {"key": key, "version": __version__, "format": CACHE_FORMAT,
              "settings": box.settings.as_dict(), "report": report, **(meta or {})}
    arrays = {
        "header": np.frombuffer(json.dumps(header, default=str).encode(), dtype=np.uint8),
        "control_points": box.control_points,
        "degree": np.asarray(box.degree, dtype=np.int64),
        "axes": np.array([box.axes.chord, box.axes.thickness, box.axes.span,
                          0 if box.axes.root == "min" else 1, int(box.axes.guessed)], dtype=np.int64),
        "dim": np.int64(box.dim),
        "chord_sign": np.float64(box.chord_sign),
        "stations": box.stations,
        "le_points": box.le_points,
        "te_points": box.te_points,
        "margins": box.margins,
        "ref_weights": box.ref_weights,
        "le_rows": box.le_rows if box.le_rows is not None else np.zeros((0, 0)),
        "imported": np.int64(box.imported),
        "surface_ids": np.asarray(surface_ids, dtype=np.int64),
        "params": embedding.params,
        "inside": embedding.inside,
        "residual": embedding.residual,
    }
    for i, k in enumerate(box.knots):
        arrays[f"knots{i}"] = k
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)


def load(path: str | Path, key: str, settings: BoxSettings):
    """(box, surface_ids, embedding, header) from a cache file, or None if absent, stale or corrupt."""
    from ffdcli.embedding import Embedding

    p = Path(path)
    if not p.is_file():
        return None
    try:
        with np.load(p, allow_pickle=False) as z:
            header = json.loads(bytes(z["header"]).decode())
            if header.get("key") != key or header.get("format") != CACHE_FORMAT \
                    or header.get("version") != __version__:
                return None
            a = {k: z[k] for k in z.files}
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError, EOFError):
        return None
    if any(v.dtype.kind == "f" and not np.all(np.isfinite(v)) for v in a.values()):
        return None                  # a damaged file: no cache we write holds NaN or inf
    try:
        dim = int(a["dim"])
        ax = a["axes"]
        axes = Axes(chord=int(ax[0]), thickness=int(ax[1]), span=int(ax[2]),
                    root="min" if ax[3] == 0 else "max", guessed=bool(ax[4]))
        nk = 3 if dim == 3 else 2
        knots = tuple(a[f"knots{i}"] for i in range(nk))
        le_rows = a["le_rows"] if a["le_rows"].size else None
        box = Box(control_points=a["control_points"], degree=tuple(int(d) for d in a["degree"]),
                  knots=knots, axes=axes, dim=dim, chord_sign=float(a["chord_sign"]),
                  stations=a["stations"], le_points=a["le_points"], te_points=a["te_points"],
                  margins=a["margins"], ref_weights=a["ref_weights"], le_rows=le_rows,
                  settings=settings, imported=bool(a["imported"]))
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
