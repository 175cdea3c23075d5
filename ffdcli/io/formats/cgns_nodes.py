"""The CGNS file as HDF5 nodes: reading a node's label, children, data and text, writing a node,
and the layout of a read file that the writers patch (:class:`CgnsZone`, :class:`CgnsSource`).
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffdcli.deferred import deferred
from ffdcli.errors import InputError
from ffdcli.mesh import CellBlock

h5py = deferred("h5py")


@dataclass
class CgnsZone:
    """Where one zone's points live in the file and in the Mesh."""

    path: str                      #: HDF5 path of the Zone_t node
    coordinates: tuple[str, ...]   #: HDF5 paths of the CoordinateX/Y(/Z) data datasets
    offset: int                    #: first point id of the zone in Mesh.points
    n_points: int
    structured: bool
    vertex_shape: tuple[int, ...]  #: (ni, nj(, nk)) for structured zones, (n,) otherwise


@dataclass
class CgnsSource:
    """What the CGNS writer needs to patch a copy of the file read."""

    container: str                 #: "hdf5" or "adf"
    zones: list[CgnsZone]
    bc_markers: dict[str, list[CellBlock]] = field(default_factory=dict)
    bc_family: dict[str, str] = field(default_factory=dict)   #: BC name -> marker name used
    skipped: list[str] = field(default_factory=list)          #: what was not read, and why


def label_of(node) -> str:
    lab = node.attrs.get("label")
    if lab is None:
        return ""
    return bytes(lab).split(b"\0", 1)[0].decode("ascii", "replace").strip()


def children_of(node, label: str) -> list:
    """Child groups of ``node`` with CGNS label ``label``, in file order."""
    return [c for c in node.values() if isinstance(c, h5py.Group) and label_of(c) == label]


def data_of(node):
    d = node.get(" data")
    return None if d is None else d[()]


def text_of(node) -> str:
    d = data_of(node)
    if d is None:
        return ""
    return np.asarray(d, dtype=np.int8).tobytes().split(b"\0", 1)[0].decode("ascii", "replace").strip()


def child_text(node, label: str) -> str | None:
    kids = children_of(node, label)
    return text_of(kids[0]) if kids else None


def check_no_links(node, file: Path) -> None:
    """InputError if a child of ``node`` is a CGNS link (node type LK) to another file or node."""
    for child in node.values():
        if isinstance(child, h5py.Group) and bytes(child.attrs.get("type", b"")).startswith(b"LK"):
            target = " ".join(np.asarray(child[k][()], dtype=np.int8).tobytes().split(b"\0")[0].decode(
                "ascii", "replace") for k in (" file", " path") if isinstance(child.get(k), h5py.Dataset))
            raise InputError(f"this node is a CGNS link ({target.strip() or 'unknown target'}); "
                             "linked CGNS files are not supported: merge them into one file first",
                             path=file, key=child.name)


def index_data(node, name: str):
    """The integer array of a standard-named child (PointList, ElementRange, ...), or None."""
    child = node.get(name)
    if not isinstance(child, h5py.Group):
        return None
    d = data_of(child)
    return None if d is None else np.asarray(d, dtype=np.int64)


def str_attr(node, name: str, value: str, size: int) -> None:
    raw = value.encode("ascii")
    if len(raw) >= size:
        raise InputError(f"name {value!r} is too long for CGNS (at most {size - 1} characters)")
    tid = h5py.h5t.C_S1.copy()
    tid.set_size(size)
    tid.set_strpad(h5py.h5t.STR_NULLTERM)
    attr = h5py.h5a.create(node.id, name.encode(), tid, h5py.h5s.create(h5py.h5s.SCALAR))
    attr.write(np.array(raw, dtype=f"S{size}"), mtype=tid)


def new_node(parent, name: str, label: str, dtype: str = "MT", data=None):
    if "/" in name or name in (".", ".."):
        raise InputError(f"name {name!r} cannot be a CGNS node name")
    g = parent.create_group(name, track_order=True)
    str_attr(g, "name", name, 33)
    str_attr(g, "label", label, 33)
    str_attr(g, "type", dtype, 3)
    g.attrs.create("flags", np.array([1], dtype=np.int32))
    if data is not None:
        arr = np.asarray(data)
        # CGNS stores Fortran-ordered arrays: HDF5 dimensions are the reversed CGNS dimensions
        g.create_dataset(" data", data=arr)
    return g


def char_array(text: str) -> np.ndarray:
    return np.frombuffer(text.encode("ascii"), dtype=np.int8)


HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: ADF files start with "@(#)" with the high bit set, then "ADF Database Version ...".
ADF_MARK = b"ADF Database"


# ----------------------------------------------------------------------------------------------
# container detection and ADF conversion

def container_of(path: str | Path) -> str:
    """``"hdf5"`` or ``"adf"`` from the first bytes of the file; InputError for anything else."""
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            head = fh.read(1024)
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror}", path=p) from None
    if head.startswith(HDF5_SIGNATURE) or h5py.is_hdf5(str(p)):
        return "hdf5"
    if ADF_MARK in head[:64]:
        return "adf"
    if not head:
        raise InputError("the file is empty, expected a CGNS mesh", path=p)
    raise InputError("not a CGNS file: neither an HDF5 nor an ADF container", path=p)


def adf_message() -> str:
    return ("this is a CGNS file in the old ADF container, which h5py cannot read; install the Debian "
            "package cgns-convert (it provides adf2hdf) or convert it with `adf2hdf IN.cgns OUT.cgns`")


def convert_adf(src: Path, dest: Path) -> None:
    """Convert the ADF CGNS file ``src`` to CGNS/HDF5 ``dest`` with ``adf2hdf``; InputError if absent."""
    exe = shutil.which("adf2hdf")
    if exe is None:
        raise InputError(adf_message(), path=src)
    # adf2hdf is a shell script that passes its arguments unquoted to cgnsconvert: work on a link
    # and an output with plain names in a private folder, so paths with spaces are safe.
    with tempfile.TemporaryDirectory(prefix="ffd-adf2hdf-") as tmp:
        link, out = Path(tmp) / "input.cgns", Path(tmp) / "output.cgns"
        link.symlink_to(src.resolve())
        try:
            proc = subprocess.run([exe, str(link), str(out)], capture_output=True, text=True,
                                  timeout=3600, cwd=tmp)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise InputError(f"adf2hdf failed: {exc}", path=src) from None
        if proc.returncode != 0 or not out.exists() or not h5py.is_hdf5(str(out)):
            why = (proc.stderr or proc.stdout).strip().splitlines()
            raise InputError("adf2hdf could not convert this ADF CGNS file"
                             + (f": {why[-1]}" if why else ""), path=src)
        shutil.move(str(out), str(dest))


# ----------------------------------------------------------------------------------------------
# reading
