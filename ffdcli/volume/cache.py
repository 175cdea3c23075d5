"""The volume warp's reference weights, kept between runs: one ``.npz`` file beside the mesh (or in
``--cache-dir``), next to the box cache (:mod:`ffdcli.box.cache`). A RANS mesh's wall layer
(:mod:`ffdcli.volume.wall_layer`: which nodes follow their wall, with which weights) is kept in the same
file: finding it walks every wall node's stack and searches the nearest wall nodes of every node near
the wall, about a fifth of a deformation of the 98k-node 32-layer wing, and it too depends on the
mesh, the surface and the settings only.

Each volume node's reference weight (:meth:`ffdcli.volume.warp.WarpModel.tolerances`) is a walk of the
source tree of its own: about a seventh of a deformation's warp on a 1M-node mesh. It depends on the
mesh, the deforming surface and the warp settings only, never on the design, so ``ffd deform`` run in a
loop over designs computes it once. A target that a wall layer moves wholly is never warped, and its
weight is never walked: NaN in the file (walked when a product asks for it). The file name carries the
key (``<mesh name>.<key>.ffdwarp.npz``): the SHA-256 of the mesh file's bytes, the surface marker
names, the warp settings (all but ``chunk``, which changes no value), the reference walk's tolerance,
the tool version and this format. A file whose key differs, that cannot be read, or whose weights do
not fit the model's volume nodes (their count and the hash of their ids, checked on every load) is not
used and is replaced atomically.

Serial runs only: an MPI rank warps its own part's nodes and computes their weights (bit for bit the
serial ones: a node's walk is its own).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ffdcli import __version__
from ffdcli.io.keyed_npz import read_keyed, write_keyed
from ffdcli.settings import WarpSettings
from ffdcli.volume.wall_layer import BLEND, MIN_ASPECT, NEIGHBOURS, SHARP_COS, STACK_SPACINGS
from ffdcli.volume.wall_stacks import MAX_LAYERS, STACK_COS

#: Bumped whenever the content of the file changes meaning (2: the wall layer's arrays beside the weights;
#: 3: NaN for the weights not walked).
CACHE_FORMAT = 3
#: The constants that decide which nodes are in the wall layer and their weights (part of the key).
LAYER_RULES = {"min_aspect": MIN_ASPECT, "blend": BLEND, "sharp_cos": SHARP_COS, "neighbours": NEIGHBOURS,
               "stack_spacings": STACK_SPACINGS, "stack_cos": STACK_COS, "max_layers": MAX_LAYERS}


def reference_key(mesh_hash: str, surface: list[str], settings: WarpSettings, reference_tolerance: float) -> str:
    """The key of a model's reference weights: mesh content, surface names, warp settings (but
    ``chunk``), the reference walk's tolerance, the wall layer's rules (:data:`LAYER_RULES`: a file
    kept under other rules holds another layer), tool version and cache format."""
    warp = {k: v for k, v in dataclasses.asdict(settings).items() if k != "chunk"}
    blob = json.dumps({"mesh": mesh_hash, "surface": list(surface), "warp": warp,
                       "reference_tolerance": float(reference_tolerance), "layer": LAYER_RULES,
                       "version": __version__, "format": CACHE_FORMAT}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()


def reference_path(mesh_path: str | Path, key: str, cache_dir: str | Path | None = None) -> Path:
    """Where the reference weights of ``mesh_path`` with ``key`` live."""
    mp = Path(mesh_path)
    folder = Path(cache_dir) if cache_dir else mp.parent
    return folder / f"{mp.name}.{key[:16]}.ffdwarp.npz"


def _ids_hash(target_ids: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(target_ids, dtype=np.int64).tobytes()).hexdigest()


def save_references(path: str | Path, key: str, target_ids: np.ndarray, weights: np.ndarray,
                    layer: dict | None = None) -> None:
    """Write the (Nt,) ``weights`` of the volume nodes ``target_ids`` (the model's order) atomically;
    ``layer``: the wall layer's arrays (:func:`ffdcli.volume.wall_layer.layer_arrays`) beside them."""
    write_keyed(path, key, CACHE_FORMAT, {"weights": np.asarray(weights, dtype=np.float64), **(layer or {})},
                targets=_ids_hash(target_ids))


def load_cache(path: str | Path, key: str, target_ids: np.ndarray) -> tuple[np.ndarray | None, dict]:
    """``(weights, layer)``: the (Nt,) reference weights of the volume nodes ``target_ids`` (the model's
    order) and the wall layer's arrays (``layer_*``; empty when none were kept), or ``(None, {})`` if the
    file is absent, stale, corrupt or of other nodes."""
    got = read_keyed(path, key, CACHE_FORMAT)
    if got is None or "weights" not in got[1]:
        return None, {}
    header, arrays = got
    w = arrays["weights"]
    if w.dtype != np.float64 or w.shape != (len(target_ids),) or header.get("targets") != _ids_hash(target_ids):
        return None, {}
    walked = ~np.isnan(w)                                  # NaN: not walked (the warp never needed it)
    if not np.all(np.isfinite(w[walked])) or np.any(w[walked] <= 0):     # a weight is a sum of positive terms
        return None, {}
    return w, {k: v for k, v in arrays.items() if k.startswith("layer_")}


def load_references(path: str | Path, key: str, target_ids: np.ndarray) -> np.ndarray | None:
    """The (Nt,) reference weights of the volume nodes ``target_ids`` (the model's order), or None if
    the file is absent, stale, corrupt or of other nodes."""
    return load_cache(path, key, target_ids)[0]


@dataclass(frozen=True)
class ReferenceCache:
    """Where one run keeps its warp's reference weights: the file, its key, and whether an existing
    file may be read (False under ``load_run(..., rebuild=True)``: computed again and replaced)."""

    path: Path
    key: str
    read: bool = True

    def load(self, target_ids: np.ndarray) -> np.ndarray | None:
        """:func:`load_references`, or None when the file is not to be read."""
        return load_references(self.path, self.key, target_ids) if self.read else None

    def load_all(self, target_ids: np.ndarray) -> tuple[np.ndarray | None, dict]:
        """:func:`load_cache`, or ``(None, {})`` when the file is not to be read."""
        return load_cache(self.path, self.key, target_ids) if self.read else (None, {})

    def save(self, target_ids: np.ndarray, weights: np.ndarray, layer: dict | None = None) -> bool:
        """:func:`save_references`; False (nothing written, the run goes on) when the folder cannot
        be written: the box cache beside it has already said so."""
        try:
            save_references(self.path, self.key, target_ids, weights, layer)
        except OSError:
            return False
        return True
