"""Input files: what is at a path, found out before opening it.

``open()`` of a FIFO blocks until someone writes to it, ``/dev/zero`` never ends and a symlink loop
fails with a message that names neither; so every input file is looked at with ``stat`` first and
anything that is not a regular file is refused with what it is.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from ffdcli.errors import InputError


def existing_kind(path: str | Path) -> str | None:
    """What exists at ``path`` (following symlinks): None (nothing), "regular file", "folder", "a FIFO
    (named pipe)", "a character device", "a block device", "a socket", "a symlink loop", ...

    Never opens the path, so a FIFO cannot block."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return "a broken symlink" if os.path.islink(path) else None
    except OSError as e:
        if e.errno == errno.ELOOP:
            return "a symlink loop"
        if e.errno == errno.ENAMETOOLONG:
            return None              # reported as a name too long by the caller
        if e.errno == errno.ENOTDIR:
            return None
        return f"not accessible ({e.strerror})"
    mode = st.st_mode
    if stat.S_ISREG(mode):
        return "regular file"
    if stat.S_ISDIR(mode):
        return "folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def check_input_file(path: str | Path, what: str = "file", *, key: str | None = None,
                     design: str | Path | None = None, line: int | None = None) -> Path:
    """``path`` as a Path if it is a regular file (or a symlink to one); else InputError saying what
    is there (nothing, a folder, a FIFO, a device, a symlink loop). ``what`` names the input in the
    message ("mesh", "sensitivity file"); ``design``/``key``/``line``: where the path was given (a
    design file's key), named instead of the path itself."""
    p = Path(path)
    kind = existing_kind(p)
    if kind == "regular file":
        return p
    if kind is None:
        text = f"{what} not found" if design is not None else "no such file"
    elif kind == "folder":
        text = (f"is a folder, expected {_article(what)}" if design is None
                else f"{what} {p} is a folder, expected a file")
    else:
        text = (f"is {kind}, expected {_article(what)} (a regular file)" if design is None
                else f"{what} {p} is {kind}, expected a regular file")
    if design is not None:
        if kind is None:
            text = f"{what} {p} not found"
        raise InputError(text, path=design, key=key, line=line)
    raise InputError(text, path=p)


def polymesh_folder_of(path: str | Path) -> Path | None:
    """The polyMesh folder of an OpenFOAM case folder (its ``constant/polyMesh``) or of a polyMesh
    folder itself (one holding ``points``, ``faces`` or ``owner``, plain or ``.gz``); None when
    ``path`` is neither."""
    p = Path(path)
    if (p / "constant" / "polyMesh").is_dir():
        return p / "constant" / "polyMesh"
    if any((p / f"{name}{gz}").is_file() for name in ("points", "faces", "owner") for gz in ("", ".gz")):
        return p
    return None


def check_mesh_path(path: str | Path, *, key: str | None = None, design: str | Path | None = None,
                    line: int | None = None) -> Path:
    """:func:`check_input_file` of a mesh, which may also be an OpenFOAM case folder (or its
    ``constant/polyMesh``): a folder is accepted when it holds a polyMesh."""
    p = Path(path)
    if existing_kind(p) != "folder":
        if existing_kind(p) is None and not p.suffix:
            text = f"no such mesh file or OpenFOAM case folder: {p}" if design is not None else \
                "no such mesh file or OpenFOAM case folder"
            raise InputError(text, path=design if design is not None else p, key=key, line=line)
        return check_input_file(p, "mesh file", key=key, design=design, line=line)
    if polymesh_folder_of(p) is None:
        text = "is a folder without an OpenFOAM mesh (no constant/polyMesh, nor polyMesh files)"
        if design is not None:
            raise InputError(f"mesh {p} {text}", path=design, key=key, line=line,
                             hint="give a mesh file or an OpenFOAM case folder")
        raise InputError(text, path=p, hint="give a mesh file or an OpenFOAM case folder")
    return p


def _article(what: str) -> str:
    """``what`` with its indefinite article: "a design file", "an airfoil file"."""
    return f"{'an' if what[:1].lower() in 'aeiou' else 'a'} {what}"
