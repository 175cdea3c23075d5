"""Cache files as ``.npz``: a JSON header (the file's key, the tool version, the cache's format, and
whatever else the writer keeps) beside named arrays, written atomically and read back only when the
header is the one asked for. The box cache (:mod:`ffdcli.box.cache`) and the warp's reference weights
(:mod:`ffdcli.volume.cache`) are such files; each checks its arrays' meaning itself.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from ffdcli import __version__
from ffdcli.io.atomic import atomic_path

#: What reading a damaged, truncated or foreign file can raise: such a file is not used.
READ_ERRORS = (OSError, ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError, EOFError,
               UnicodeDecodeError)


def write_keyed(path: str | Path, key: str, fmt: int, arrays: dict, **header) -> None:
    """Write ``arrays`` (name -> ndarray) and the header ``{key, version, format, **header}`` to
    ``path`` atomically (a complete file or none)."""
    head = {"key": key, "version": __version__, "format": fmt, **header}
    blob = np.frombuffer(json.dumps(head, default=str).encode(), dtype=np.uint8)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, header=blob, **arrays)


def read_keyed(path: str | Path, key: str, fmt: int) -> tuple[dict, dict] | None:
    """``(header, arrays)`` of a file :func:`write_keyed` wrote with this ``key`` and format, by this
    version of the tool; None if the file is absent, unreadable, or of another key, format or
    version (``arrays`` holds every array but the header)."""
    p = Path(path)
    if not p.is_file():
        return None
    try:
        with np.load(p, allow_pickle=False) as z:
            header = json.loads(bytes(z["header"]).decode())
            if not isinstance(header, dict):         # valid JSON, but not what we write
                return None
            if header.get("key") != key or header.get("format") != fmt or header.get("version") != __version__:
                return None
            arrays = {k: z[k] for k in z.files if k != "header"}
    except READ_ERRORS:
        return None
    return header, arrays
