"""Room for an output file: the process's file-size limit (``ulimit -f``, RLIMIT_FSIZE) and the free
space of the file system, for the writers that cannot report a failed write themselves.

Most writers fail with an ``OSError`` whose errno says why (ENOSPC, EFBIG), which the output plan turns
into one line naming the file (:func:`ffdcli.io.atomic.output_error`). Two do not: HDF5 (h5py) after a
failed write leaves objects that crash the interpreter at exit, so a new HDF5 file is checked before it
is written (:func:`check_room`); NumPy's ``tofile`` (meshio's legacy VTK writer) raises an OSError
without an errno, whose cause :func:`diagnosed` finds again.
"""

from __future__ import annotations

import errno
import os
import resource
import shutil
from pathlib import Path


def file_size_limit() -> int | None:
    """The soft limit on the size of a file this process writes, in bytes (None: none)."""
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    return None if soft == resource.RLIM_INFINITY else int(soft)


def free_bytes(path: str | Path) -> int | None:
    """The bytes free for this user on the file system of ``path``'s folder (None when unknown)."""
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    try:
        return shutil.disk_usage(folder).free
    except OSError:
        return None


def check_room(path: str | Path, nbytes: int) -> None:
    """OSError (EFBIG, ENOSPC) when a file of ``nbytes`` cannot be written at ``path``: over the
    process's file-size limit or the free space of its file system."""
    limit = file_size_limit()
    if limit is not None and nbytes > limit:
        raise OSError(errno.EFBIG, os.strerror(errno.EFBIG), str(path))
    free = free_bytes(path)
    if free is not None and nbytes > free:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))


def diagnosed(e: OSError, written: str | Path) -> OSError:
    """``e`` with an errno: an OSError without one (NumPy's "problem writing element ...") while writing
    the file ``written`` is EFBIG when that file reached the file-size limit, ENOSPC when the file system
    is full; else ``e`` as it is."""
    if e.errno is not None:
        return e
    try:
        size = os.stat(written).st_size
    except OSError:
        size = None
    limit = file_size_limit()
    if limit is not None and size is not None and size >= limit:
        return OSError(errno.EFBIG, os.strerror(errno.EFBIG), str(written))
    free = free_bytes(written)
    if free is not None and free < 65536:
        return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(written))
    return e
