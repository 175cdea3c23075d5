"""The markers of a CGNS file: its boundary conditions (``BC_t``: point ranges, lists, element
ranges; families and their names) as named sets of faces.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ffdcli.errors import InputError
from ffdcli.io.formats.cgns_cells import TYPE_ORDER, Section, outward_faces, range_faces, sections_cells
from ffdcli.io.formats.cgns_nodes import CgnsSource, CgnsZone, child_text, index_data
from ffdcli.mesh import CELL_DIM, CellBlock, Mesh
from ffdcli.mesh.idsets import unique_ids

#: family names that mean "no family" (defaults written by meshers)
PLACEHOLDER_FAMILIES = frozenset({"", "unspecified", "unspecifiedbc", "null"})


@dataclass
class MarkerSet:
    """Markers being collected: primary names (family or BC), BC names, and where each came from."""

    markers: dict[str, list[CellBlock]] = field(default_factory=dict)
    by_bc: dict[str, list[CellBlock]] = field(default_factory=dict)
    bc_family: dict[str, str] = field(default_factory=dict)
    from_bc: set[str] = field(default_factory=set)

    def add_bc(self, bc_name: str, marker: str, blocks: list[CellBlock]) -> None:
        self.markers.setdefault(marker, []).extend(blocks)
        self.by_bc.setdefault(bc_name, []).extend(blocks)
        self.bc_family[bc_name] = marker
        self.from_bc.add(marker)


def _bc_location(bc) -> str:
    return (child_text(bc, "GridLocation_t") or "Vertex").strip()


def bc_marker_name(bc) -> tuple[str, str]:
    bc_name = bc.name.rsplit("/", 1)[-1]
    fam = child_text(bc, "FamilyName_t")
    if fam is not None and fam.lower() not in PLACEHOLDER_FAMILIES:
        return bc_name, fam
    return bc_name, bc_name


def unstructured_bc(bc, zone: CgnsZone, sections: list[Section], cell_dim: int, file: Path,
                     used: set[int]) -> list[CellBlock]:
    loc = _bc_location(bc)
    plist = index_data(bc, "PointList")
    prange = index_data(bc, "PointRange")
    elist = index_data(bc, "ElementList")
    erange = index_data(bc, "ElementRange")

    def expand(lst, rng):
        if lst is not None:
            return lst.ravel()
        lo, hi = (int(v) for v in rng.ravel()[:2])
        return np.arange(min(lo, hi), max(lo, hi) + 1, dtype=np.int64)

    if elist is not None or erange is not None:
        ids = expand(elist, erange)
    elif (plist is not None or prange is not None) and loc != "Vertex":
        ids = expand(plist, prange)
    else:
        ids = None
    if ids is not None:
        cells, touched = sections_cells(sections, ids, file, bc.name)
        used |= touched
        return [CellBlock(t, np.vstack(cells[t])) for t in TYPE_ORDER if t in cells]
    if plist is None and prange is None:
        raise InputError("boundary condition has no PointList, PointRange, ElementList or ElementRange",
                         path=file, key=bc.name)
    pts = expand(plist, prange)
    if len(pts) and (pts.min() < 1 or pts.max() > zone.n_points):
        raise InputError(f"boundary condition refers to points outside 1..{zone.n_points} of its zone",
                         path=file, key=bc.name)
    gids = unique_ids(pts - 1 + zone.offset)
    # faces of the boundary sections whose nodes all belong to the BC's points
    inside = np.zeros(zone.n_points, dtype=bool)
    inside[gids - zone.offset] = True
    faces: dict[str, list[np.ndarray]] = {}
    hit = set()
    for si, s in enumerate(sections):
        whole = True
        for t, c in s.blocks.items():
            if CELL_DIM[t] >= cell_dim:
                continue
            keep = inside[c - zone.offset].all(axis=1)
            whole &= bool(keep.all())
            if keep.any():
                faces.setdefault(t, []).append(c[keep])
        if whole and any(CELL_DIM[t] < cell_dim for t in s.blocks):
            hit.add(si)
    if faces:
        covered = unique_ids(*[np.vstack(v) for v in faces.values()])
        if len(covered) == len(gids):
            used |= hit
            return [CellBlock(t, np.vstack(faces[t])) for t in TYPE_ORDER if t in faces]
    return [CellBlock("vertex", gids[:, None])]


def structured_bc(bc, zone: CgnsZone, file: Path, handed: int = 0) -> list[CellBlock]:
    loc = _bc_location(bc)
    shape = np.asarray(zone.vertex_shape)
    idim = len(shape)
    prange = index_data(bc, "PointRange")
    plist = index_data(bc, "PointList")
    if prange is not None:
        pr = prange.reshape(2, idim)
        lo, hi = np.minimum(pr[0], pr[1]) - 1, np.maximum(pr[0], pr[1]) - 1
        axis = None
        if loc != "Vertex":
            # a face-centred range counts faces: constant (vertex) index on the face's axis, cell
            # indices on the others, so its vertex range reaches one further on the free axes
            flats = [a for a in range(idim) if lo[a] == hi[a]]
            if len(loc) == 11 and loc[0] in "IJK" and loc.endswith("FaceCenter"):
                axis = "IJK".index(loc[0])
            elif loc in ("FaceCenter", "EdgeCenter") and flats:
                on_side = [a for a in flats if lo[a] == 0 or lo[a] == shape[a] - 1]
                axis = (on_side or flats)[0]
            else:
                raise InputError(f"a structured BC located at {loc} is not supported (expected Vertex "
                                 "or a face centre)", path=file, key=bc.name)
            hi = hi + (np.arange(idim) != axis)
        if lo.min() < 0 or np.any(hi >= shape):
            raise InputError(f"PointRange {pr.tolist()} is outside the zone's {shape.tolist()} vertices",
                             path=file, key=bc.name)
        faces = range_faces(tuple(shape), zone.offset, lo, hi, axis)
        if faces.type == "quad" and axis is None:
            axis = int(np.flatnonzero(lo == hi)[0])
        return [outward_faces(faces, tuple(shape), lo, axis, handed)]
    if plist is not None:
        ijk = plist.reshape(-1, idim) - 1
        if loc != "Vertex":
            raise InputError(f"a face-centred PointList ({loc}) on a structured zone is not supported",
                             path=file, key=bc.name)
        if len(ijk) and (ijk.min() < 0 or np.any(ijk >= shape)):
            raise InputError("PointList refers to points outside the zone", path=file, key=bc.name)
        strides = np.concatenate([[1], np.cumprod(shape[:-1])])
        return [CellBlock("vertex", (zone.offset + ijk @ strides)[:, None])]
    raise InputError("boundary condition of a structured zone has no PointRange or PointList",
                     path=file, key=bc.name)


def markers_by_bc(mesh: Mesh) -> dict[str, list[CellBlock]]:
    """The markers of a mesh read from CGNS keyed by BC name instead of family name."""
    if isinstance(mesh.source, CgnsSource):
        return mesh.source.bc_markers
    return {}
