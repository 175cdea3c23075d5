"""Whole-or-nothing file writes.

Every output goes to a temporary file in the destination folder and is renamed over the
destination only when complete, so an error, a full disk, Ctrl-C, SIGTERM or SIGHUP never leaves a
half-written file, and two processes writing the same file never interleave.

Temporary files are named ``.<name>.<host>-<pid>-<random>.part<suffix>``, one per output: a writer
handed such a path (the output plan gives each writer its temporary file) writes it in place instead
of nesting a temporary file of its own (:func:`is_temp`). A run that is killed outright (SIGKILL, the
OOM killer, a power cut) cannot remove its own: the next write into the same folder removes those that
are stale, i.e. written by a process of this host that no longer runs, or (any other name of this
form, e.g. from another host of a shared file system) not modified for :data:`STALE_AGE` seconds;
nested ones of older versions (``..<name>.….part<suffix>.….part<suffix>``) too. A live process's
temporary file is never touched.

:func:`output_error` turns an ``OSError`` of a write into the one-line error the user sees.
"""

from __future__ import annotations

import contextlib
import errno
import glob
import os
import re
import shutil
import signal
import socket
import stat
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from ffdcli.errors import FfdError, InputError, Terminated, committed_outputs
from ffdcli.io.inputs import existing_kind

#: A temporary file of another host (or of the old naming) untouched this long is stale (seconds).
STALE_AGE = 3600.0

#: Signals that end a write cleanly (temporary files removed) instead of killing the process.
HANDLED_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))


def check_writable(path: str | Path, *, inputs: tuple[str | Path, ...] = ()) -> Path:
    """Return ``path`` as a Path after checking that it can be written as an output.

    Raises InputError if its folder does not exist or is not writable, if it is a folder or any
    other existing thing that is not a regular file (a FIFO, a device, a symlink loop), or if it is
    one of ``inputs`` (the input mesh, first, and any other input file are never overwritten).
    """
    p = Path(path)
    if not str(path):
        raise InputError("the output file name is empty", hint="give a file name")
    check_not_input(p, inputs)
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"the output folder {str(parent)!r} does not exist", path=p,
                         hint="create it first")
    kind = existing_kind(p)
    if kind == "folder":
        raise InputError("the output path is a folder, expected a file name", path=p)
    if kind not in (None, "regular file"):
        raise InputError(f"the output path exists and is {kind}; outputs are written only as regular "
                         "files", path=p, hint="choose another output path")
    if not os.access(parent, os.W_OK):
        raise InputError(f"the output folder {str(parent)!r} is not writable", path=p)
    if kind is not None and not os.access(p, os.W_OK):
        raise InputError("the output file exists and is read-only", path=p)
    name_max = _name_max(parent)
    if len(os.fsencode(p.name)) > name_max:
        raise InputError(f"the file name is too long ({len(os.fsencode(p.name))} bytes; this file system "
                         f"allows {name_max})", path=p, hint="choose a shorter name")
    return p


def check_not_input(path: Path, inputs: tuple[str | Path | None, ...]) -> None:
    """InputError if ``path`` is one of ``inputs`` (the first is the input mesh)."""
    for index, src in enumerate(inputs):
        if src is not None and _same_file(Path(path), Path(src)):
            what = "the input mesh" if index == 0 else f"{Path(src).name}, which this run also uses"
            raise InputError(f"the output would overwrite {what}; choose another output path", path=path)


def _name_max(folder: Path) -> int:
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError):
        return 255


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    try:
        return a.resolve() == b.resolve()
    except (OSError, RuntimeError):
        return False


# ----------------------------------------------------------------------------------------------
# Temporary files: names, creation, the sweep of stale ones
# ----------------------------------------------------------------------------------------------

_HOST = socket.gethostname().replace(".", "_").replace("-", "_")[:32] or "host"


def _temp_prefix(p: Path) -> str:
    """``.<name>.`` with the name cut so that the whole temporary name fits the file system."""
    room = _name_max(p.parent if str(p.parent) else Path(".")) - 80 - len(os.fsencode(p.suffix))
    name = p.name
    while len(os.fsencode(name)) > max(room, 1):
        name = name[:-1]
    return f".{name}."


def is_temp(path: str | Path) -> bool:
    """Whether ``path`` is named as a temporary file of ours (``.<name>.<host>-<pid>-<random>.part<suffix>``):
    a writer given one writes it in place (whoever made it renames it), so an output has one temporary file."""
    name = Path(path).name
    m = _TEMP_NAME.search(name)
    return name.startswith(".") and m is not None and m["pid"] is not None


def make_temp(path: str | Path) -> Path:
    """Create an empty temporary file beside ``path`` (named as the module says) and return it.

    Stale temporary files in that folder are removed first (:func:`sweep_stale`)."""
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    sweep_stale(p)
    tmp = None
    try:
        with signals_deferred():      # a signal right now would leave a file whose name we do not know
            fd, name = tempfile.mkstemp(prefix=f"{_temp_prefix(p)}{_HOST}-{os.getpid()}-",
                                        suffix=".part" + p.suffix, dir=folder)
            tmp = Path(name)
            os.close(fd)
    except BaseException:             # the signal held above, raised now: the file goes too
        if tmp is not None:
            with contextlib.suppress(OSError):
                tmp.unlink()
        raise
    return tmp


def sweep_stale(path: str | Path, *, now: float | None = None) -> list[Path]:
    """Remove the stale temporary files in the folder of output ``path``; returns those removed.

    Ours (``.<name>.<host>-<pid>-...part...``, of any output, nested or not): stale when written on this
    host by a process that no longer exists; those of the output ``path`` (or nested ones, which no
    version writes any more) also when untouched for :data:`STALE_AGE` seconds. A live writer's file
    stays."""
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    now = time.time() if now is None else now
    removed = []
    own = _temp_prefix(p)
    for name in glob.glob(os.path.join(glob.escape(str(folder)), ".*.part*"), include_hidden=True):
        q = Path(name)
        if not _is_stale(q, q.name.startswith(own) or q.name.count(".part") > 1, now):
            continue
        with contextlib.suppress(OSError):
            st = os.lstat(q)
            if stat.S_ISREG(st.st_mode):
                q.unlink()
                removed.append(q)
            elif stat.S_ISDIR(st.st_mode):        # a folder output (an OpenFOAM case) or the one it replaced
                shutil.rmtree(q)
                removed.append(q)
    return removed


def replace_folder(tmp: Path, dest: Path) -> None:
    """Put the finished folder ``tmp`` at ``dest``: renamed into place; an existing ``dest`` (the
    caller checked it may be replaced) is first renamed aside to a temporary name beside it (which
    :func:`sweep_stale` removes if the process dies before it is deleted), then deleted. Call with
    signals deferred."""
    if not dest.exists() and not dest.is_symlink():
        os.replace(tmp, dest)
        return
    folder = dest.parent if str(dest.parent) else Path(".")
    aside = Path(tempfile.mkdtemp(prefix=f"{_temp_prefix(dest)}{_HOST}-{os.getpid()}-", suffix=".part", dir=folder))
    os.replace(dest, aside)                       # onto the empty folder just made
    try:
        os.replace(tmp, dest)
    except OSError:
        os.replace(aside, dest)                   # put the old one back
        raise
    shutil.rmtree(aside, ignore_errors=True)


#: The end of a temporary file's name: ``.<host>-<pid>-<random>.part<suffix>`` (host and pid absent
#: in the oldest naming); a nested name ends with the inner writer's.
_TEMP_NAME = re.compile(r"\.(?:(?P<host>[A-Za-z0-9_]+)-(?P<pid>[0-9]+)-)?[a-z0-9_]+\.part(?:\.[^.]*)?$")


def _is_stale(q: Path, by_age: bool, now: float) -> bool:
    """``q`` is a temporary file of ours whose writer is gone: a process of this host that no longer
    runs, or (``by_age``: a file of this output, or a nested one) untouched for :data:`STALE_AGE` s."""
    m = _TEMP_NAME.search(q.name)
    if m is None:                    # not a temporary file of ours: never touched
        return False
    if m["host"] == _HOST:
        pid = int(m["pid"])
        if pid == os.getpid():
            return False
        if not _pid_alive(pid):
            return True
    if not by_age:
        return False
    try:
        return now - os.lstat(q).st_mtime > STALE_AGE
    except OSError:
        return False


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


# ----------------------------------------------------------------------------------------------
# Signals during writes
# ----------------------------------------------------------------------------------------------

@contextlib.contextmanager
def _handlers(signals, handler, old: dict, *, keep_user: bool) -> Iterator[None]:
    """``handler`` for ``signals`` during the block, the previous handlers (recorded in ``old``) after.
    ``keep_user``: leave a signal alone whose handler is not the default (the user program's own)."""
    for s in signals:
        try:
            current = signal.getsignal(s)       # ffd's own recorder (MPI runs) gives way too
            if not keep_user or current == signal.SIG_DFL or getattr(current, "ffd_replaceable", False):
                old[s] = signal.signal(s, handler)
        except (ValueError, OSError):
            pass
    try:
        yield
    finally:
        for s, h in old.items():
            if h == signal.SIG_DFL and s != signal.SIGINT and committed_outputs():
                h = raise_terminated          # outputs are complete: a later signal must say so, not kill
            with contextlib.suppress(ValueError, OSError):
                signal.signal(s, h)


def raise_terminated(signum, frame):
    """The handler of SIGTERM and SIGHUP once the command's outputs are complete
    (:func:`ffdcli.errors.committed_outputs`): :class:`Terminated`, whose message names them, instead of
    the default death without a word; :func:`ffdcli.errors.outputs_ledger` puts the default back."""
    raise Terminated(signum)


@contextlib.contextmanager
def signals_raise() -> Iterator[None]:
    """During the block SIGTERM and SIGHUP raise :class:`Terminated` (SIGINT raises KeyboardInterrupt as
    always; under MPI, where ffd's recorder holds it, it raises here too), so the temporary files are
    removed on the way out; once: a second signal while the first unwinds does not interrupt the
    clean-up (under MPI it is recorded). A handler set by the user's program (not the default) is left
    alone. Outside the main thread: a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    fired: list[int] = []
    replaced: dict = {}

    def handler(signum, frame):
        if fired:              # the run is already stopping: a second signal (mpiexec forwards Ctrl-C that a
            outer = replaced.get(signum)      # terminal also delivers) must not raise again in the clean-up
            if getattr(outer, "ffd_replaceable", False):
                outer(signum, frame)          # or in the ranks' agreement: recorded, as outside a write
            return
        fired.append(signum)
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        raise Terminated(signum)

    with _handlers(HANDLED_SIGNALS, handler, replaced, keep_user=True):
        yield


@contextlib.contextmanager
def signals_deferred() -> Iterator[None]:
    """Postpone SIGINT, SIGTERM and SIGHUP to the end of the block; then act on the first as usual
    (KeyboardInterrupt, :class:`Terminated`, or the handler that was there).

    Python runs signal handlers in the main thread only, so swapping the handler there defers the
    signal whichever thread it arrived on. Elsewhere (other threads) a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got: list[int] = []
    old: dict = {}
    try:
        with _handlers(HANDLED_SIGNALS, lambda signum, frame: got.append(signum), old, keep_user=False):
            yield
    finally:
        if got:
            s = got[0]
            h = old.get(s, signal.SIG_DFL)
            if callable(h):
                h(s, None)
            elif h == signal.SIG_DFL:
                if s == signal.SIGINT:
                    raise KeyboardInterrupt
                raise Terminated(s)


# ----------------------------------------------------------------------------------------------
# One file, whole or nothing
# ----------------------------------------------------------------------------------------------

@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it is renamed to ``path``.

    For writers that take a file name (meshio, h5py, numpy). On any exception (including
    KeyboardInterrupt, SIGTERM and SIGHUP) the temporary file is removed and ``path`` is left as it
    was. Several outputs that must appear together: :class:`ffdcli.io.outputs.OutputPlan`.
    """
    p = Path(path)
    if is_temp(p):                   # already a temporary file (the output plan's): one per output
        yield p
        return
    tmp_path = None
    try:
        with signals_raise():
            tmp_path = make_temp(p)
            yield tmp_path
            with signals_deferred():
                keep_mode(p, tmp_path)
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


def keep_mode(dest: Path, tmp: Path) -> None:
    """Give the new file the permissions a normally created file would have (or the old file's).
    A folder keeps the permissions it was made with."""
    if tmp.is_dir():
        return
    try:
        mode = dest.stat().st_mode & 0o777 if dest.exists() else 0o666 & ~_umask()
        os.chmod(tmp, mode)
    except OSError:
        pass


_keep_mode = keep_mode


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# ----------------------------------------------------------------------------------------------
# OS errors of a write, as the user sees them
# ----------------------------------------------------------------------------------------------

#: errno -> (exit status, what to say). 2: the user can fix the path; 1: the machine's state.
_WRITE_ERRORS = {
    errno.ENOSPC: (1, "no space left on the device", "free some space or write elsewhere"),
    errno.EDQUOT: (1, "disk quota exceeded", "free some space or write elsewhere"),
    errno.EFBIG: (1, "the file is larger than this process may write (its file-size limit, `ulimit -f`) or than "
                     "the file system allows", "raise the limit or write elsewhere"),
    errno.EIO: (1, "input/output error of the device", None),
    errno.ENAMETOOLONG: (2, "the file name is too long", "choose a shorter name"),
    errno.EACCES: (2, "permission denied", "choose a writable folder"),
    errno.EPERM: (2, "operation not permitted", "choose a writable folder"),
    errno.EROFS: (2, "the file system is read-only", "write elsewhere"),
    errno.ENOENT: (2, "the folder does not exist (any more)", None),
    errno.ENOTDIR: (2, "a part of the path is not a folder", None),
    errno.EISDIR: (2, "is a folder", None),
    errno.EXDEV: (1, "cannot rename across file systems", None),
}


def output_error(e: OSError, path: str | Path, what: str = "the output", done: str = "nothing was written") -> FfdError:
    """The one-line error of an OSError while writing ``what`` to ``path``; ``done``: what the files are
    now (by default: nothing was written)."""
    code, text, hint = _WRITE_ERRORS.get(e.errno, (1, e.strerror or str(e), None))
    cls = InputError if code == 2 else FfdError
    return cls(f"cannot write {what}: {text}; {done}", path=path, hint=hint)


@contextlib.contextmanager
def written_as(path: str | Path, what: str = "the output", done: str = "nothing was written") -> Iterator[None]:
    """During the block an OSError (a full disk, a quota, an I/O error) of writing ``what`` to ``path``
    becomes the one-line error of :func:`output_error`, naming the file (never a temporary one): for
    writes outside an :class:`~ffdcli.io.outputs.OutputPlan` (``ffd optimize``'s evaluations and
    results); ``done``: what the files are now."""
    try:
        yield
    except OSError as e:
        raise output_error(e, path, what, done) from None
