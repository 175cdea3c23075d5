"""Whole-or-nothing file writes.

Every output goes to a temporary file in the destination folder and is renamed over the
destination only when complete, so an error, a full disk or Ctrl-C never leaves a half-written
file, and two processes writing the same file never interleave.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from ffdcli.errors import InputError


def check_writable(path: str | Path, *, inputs: tuple[str | Path, ...] = ()) -> Path:
    """Return ``path`` as a Path after checking that it can be written as an output.

    Raises InputError if its folder does not exist or is not writable, if it is a folder, or if
    it is one of ``inputs`` (the input mesh, first, and any other input file are never overwritten).
    """
    p = Path(path)
    for index, src in enumerate(inputs):
        if src is not None and _same_file(p, Path(src)):
            what = "the input mesh" if index == 0 else f"{Path(src).name}, which this run also uses"
            raise InputError(f"the output would overwrite {what}; choose another output path", path=p)
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"the output folder {str(parent)!r} does not exist", path=p,
                         hint="create it first")
    if p.is_dir():
        raise InputError("the output path is a folder, expected a file name", path=p)
    if not os.access(parent, os.W_OK):
        raise InputError(f"the output folder {str(parent)!r} is not writable", path=p)
    if p.exists() and not os.access(p, os.W_OK):
        raise InputError("the output file exists and is read-only", path=p)
    return p


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it is renamed to ``path``.

    For writers that take a file name (meshio, h5py, numpy). On any exception (including
    KeyboardInterrupt) the temporary file is removed and ``path`` is left as it was.
    """
    p = Path(path)
    tmp_path = None
    try:
        # Ctrl-C between creating the temporary file and knowing its name would leave it behind:
        # hold SIGINT until the name is known (a pending one is raised right after, inside this try).
        with _sigint_deferred():
            fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".part" + p.suffix, dir=p.parent or ".")
            tmp_path = Path(tmp)
            os.close(fd)
        yield tmp_path
        _keep_mode(p, tmp_path)
        os.replace(tmp_path, p)
    except BaseException:
        if tmp_path is not None:
            with contextlib.suppress(OSError):
                tmp_path.unlink()
        raise


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "wb") -> Iterator:
    """Open a temporary file for writing; it replaces ``path`` when the block ends without error."""
    with atomic_path(path) as tmp, open(tmp, mode) as fh:
        yield fh
        fh.flush()
        os.fsync(fh.fileno())


def _keep_mode(dest: Path, tmp: Path) -> None:
    """Give the new file the permissions a normally created file would have."""
    try:
        mode = dest.stat().st_mode & 0o777 if dest.exists() else 0o666 & ~_umask()
        os.chmod(tmp, mode)
    except OSError:
        pass


@contextlib.contextmanager
def _sigint_deferred():
    """Postpone Ctrl-C (SIGINT) to the end of the block; then raise it as usual.

    Python runs signal handlers in the main thread only, so swapping the handler there defers the
    KeyboardInterrupt whichever thread the signal arrived on. Elsewhere (other threads) a no-op."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got = []
    try:
        old = signal.signal(signal.SIGINT, lambda signum, frame: got.append(signum))
    except (ValueError, OSError):
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)
        if got:
            if callable(old):
                old(signal.SIGINT, None)
            elif old != signal.SIG_IGN:
                raise KeyboardInterrupt


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
