"""The starter design file of ``ffd init MESH``: a commented YAML text for one mesh.

:func:`starter_design` reads the mesh, finds the wing surface and its axes exactly as ``ffd box``
does, and returns the text of a design file in which every line says what it means. Every change
kind is present but commented out, so ``ffd deform`` of the unedited file writes the input mesh
back (the surface moves by ``B @ 0``); uncommenting one change line gives a valid design. The
``volume:`` block is written from the fields of :class:`~ffdcli.volume.warp.WarpSettings` that the design
schema knows, so its values are the defaults a run uses.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from ffdcli import __version__
from ffdcli.app.design_output import plan_design_output, write_design_text
from ffdcli.app.prepare import resolve_surface, space_dim
from ffdcli.design import design_schema
from ffdcli.errors import InputError
from ffdcli.geometry.axes import AXIS_NAMES, detect_axes
from ffdcli.geometry.surface import extract_surface
from ffdcli.io.atomic import output_error
from ffdcli.io.formats import read_mesh
from ffdcli.io.inputs import existing_kind
from ffdcli.quality.rules import DEFAULT_THRESHOLD
from ffdcli.settings import DEFAULT_POINTS
from ffdcli.volume.extruded import one_cell_thick
from ffdcli.volume.warp import WarpSettings

#: Column where the ``#`` of a value's comment starts.
COMMENT_COLUMN = 44


def _flow(value) -> str:
    """A YAML flow-style scalar or list (quoted where YAML needs it, e.g. a marker named ``1``)."""
    text = yaml.safe_dump(value, default_flow_style=True, width=10**6).strip()
    return text[:-4].strip() if text.endswith("\n...") else text


#: Longest line written; a longer comment goes on its own lines above the value.
WIDTH = 110


def _line(text: str, comment: str = "") -> str:
    """``text`` with ``comment`` at :data:`COMMENT_COLUMN` (or wrapped above it when too long)."""
    if not comment:
        return text
    one = f"{text:<{COMMENT_COLUMN - 1}} # {comment}" if len(text) < COMMENT_COLUMN - 1 else \
        f"{text}  # {comment}"
    if len(one) <= WIDTH:
        return one
    indent = " " * (len(text) - len(text.lstrip()))
    wrapped = textwrap.wrap(comment, WIDTH - len(indent) - 2)
    return "\n".join([f"{indent}# {w}" for w in wrapped] + [text])


def _round(x: float) -> float:
    """``x`` to two significant digits (a readable example value in mesh units)."""
    if x == 0 or not np.isfinite(x):
        return 0.0
    return float(f"{x:.2g}")


def volume_defaults() -> list[tuple[str, object, str]]:
    """(key, default, meaning) of every ``volume:`` setting of the design schema, from WarpSettings."""
    known = design_schema()["properties"]["volume"]["properties"]
    out = []
    for f in dataclasses.fields(WarpSettings):
        if f.name in known:
            out.append((f.name, f.default, f.metadata.get("doc", "")))
    if "threshold" in known:
        out.append(("threshold", DEFAULT_THRESHOLD, known["threshold"].get("description", "")))
    return out


def starter_design(mesh_path, surface=None, *, design_path=None, progress=None) -> str:
    """The text of a commented starter design file for the mesh at ``mesh_path``.

    Parameters
    ----------
    mesh_path : path-like
        The mesh (.su2, .cgns, .vtu, .vtk).
    surface : str or list of str, optional
        The wing marker(s); default the rule of ``ffd box`` (the only marker, or the only one that
        does not look like a domain boundary).
    design_path : path-like, optional
        Where the design file will be written: the ``mesh:`` line is relative to its folder and
        the outputs are named after its stem. Default ``<mesh stem>.yaml`` beside the mesh.
    progress : callable, optional
        A progress factory of :mod:`ffdcli.progress` for reading the mesh.

    Returns
    -------
    str
        YAML text; loading it gives a valid design without changes.
    """
    mesh_path = Path(mesh_path)
    design_path = Path(design_path) if design_path is not None else default_design_path(mesh_path)
    mesh = read_mesh(mesh_path, progress=progress)
    names = resolve_surface(mesh, surface)
    surf = extract_surface(mesh, names)
    if len(surf.ids) == 0:
        raise InputError(f"the surface marker(s) {', '.join(names)} have no points", path=mesh_path)
    dim = space_dim(mesh)

    extrusion = one_cell_thick(mesh, names)
    axes = detect_axes(surf.points, dim, sections=extrusion.sections if extrusion else None,
                       path=mesh_path, faces=surf.faces)
    points = DEFAULT_POINTS[dim]
    ext = np.ptp(surf.points, axis=0)
    chord = float(ext[axes.chord])
    others = [m for m in mesh.markers if m not in names]

    rel = _relative(mesh_path, design_path.parent)
    stem = design_path.stem
    c, t, s = (AXIS_NAMES[a] for a in (axes.chord, axes.thickness, axes.span))
    L = []
    add = L.append
    add(f"# ffd design file for {mesh_path.name}: a starter written by `ffd init` (ffd {__version__}).")
    add("# As written it changes nothing: `ffd deform` of it writes the input mesh back. Uncomment a")
    add("# change (delete the leading '# ') and edit its numbers; `ffd plot` draws the result, `ffd vars`")
    add("# lists the design variables, `ffd schema` prints every key. Paths are relative to this file.")
    if extrusion is not None:
        add("#")
        for w in textwrap.wrap("WARNING: " + extrusion.message() + " (box.sections below is set so).",
                               WIDTH - 2):
            add("# " + w)
    add("")
    add(_line(f"mesh: {_flow(rel)}", "the mesh; the format comes from the extension"))
    add(_line(f"surface: {_flow(names[0] if len(names) == 1 else names)}",
              "the wing marker(s) the lattice wraps" + (f"; the others: {', '.join(others)}"
                                                        if others else "")))
    add(_line("box:", "the lattice of B-spline control points around the wing"))
    if dim == 3:
        add(_line(f"  points: {_flow(list(points))}",
                  "control points: chordwise, spanwise (sections root to tip), thickness"))
        add(_line("  # degree: [3, 3, 1]", "B-spline degree per direction; default min(3, points - 1)"))
        guess = " (the extrusion is the span)" if extrusion else \
            "; detected, a guess: check it" if axes.guessed else " (detected)"
        add(_line(f"  sections: {axes.sections}",
                  f"airfoil sections in the {c}-{t} plane: chord along {c}, thickness along {t}, "
                  f"span along {s}{guess}"))
        add(_line(f"  root: {axes.root}", f"the root section is at the {axes.root} end of {s} "
                                          "(detected: the end nearer 0)"))
    else:
        add(_line(f"  points: {_flow(list(points))}", "control points: chordwise, thickness (2D)"))
        add(_line("  # degree: [3, 1]", "B-spline degree per direction; default min(3, points - 1)"))
        guess = "; detected, a guess: check it" if axes.guessed else " (detected)"
        add(_line(f"  sections: {axes.sections}",
                  f"the airfoil plane: chord along {c}, thickness along {t}{guess}"))
    add(_line("  margin: 0.02", "clearance around the wing, fraction of the local chord"))
    add(_line("volume:", "how the rest of the mesh follows the surface (the defaults)"))
    for key, value, doc in volume_defaults():
        if value is None:
            add(_line(f"  # {key}:", doc))
        else:
            add(_line(f"  {key}: {_flow(value)}", doc))
    add(_line("changes:", "applied in this order; each item has exactly one key"))
    for text, comment in _change_examples(dim, points, chord):
        add(_line(f"  # {text}", comment) if text else f"  #   {comment}")
    add(_line("output:", "written whole or not at all; the input is never overwritten"))
    add(_line(f"  mesh: {_flow('out/' + stem + mesh_path.suffix)}", "the deformed mesh, every marker kept"))
    add(_line(f"  lattice: {_flow('out/' + stem + '_lattice.vtk')}",
              "original and deformed lattice (ParaView)"))
    add(_line(f"  plot: {_flow('out/' + stem + '.png')}",
              "where `ffd plot` (and `ffd deform --plot`) put the picture; ffd deform draws none without --plot"))
    return "\n".join(L) + "\n"


@dataclass(frozen=True)
class InitReport:
    """What ``ffd init`` wrote: the design file, the folder made for its outputs, the summary and text."""

    design: str
    mesh: str
    out_folder: str
    summary: dict
    text: str


def init_design(mesh_path, surface=None, *, output=None, force: bool = False, progress=None) -> InitReport:
    """``ffd init``'s workflow: the starter design file of ``mesh_path`` written at ``output`` (default
    :func:`default_design_path`), and the folder ``out/`` beside it where its outputs go.

    The design file is checked before the mesh is read (a ``.yaml`` name, a writable folder, not the
    mesh, not an existing file without ``force``); it is written whole or not at all, and a write that
    fails (a full disk, a file-size limit, a read-only file system) is one line naming the file."""
    out = Path(output) if output is not None else default_design_path(mesh_path)
    plan = plan_design_output(out, inputs=(mesh_path,), force=force)
    folder = out.parent / "out"               # where its outputs go (output: out/...)
    kind = existing_kind(folder)
    if kind not in (None, "folder"):
        raise InputError(f"the design's outputs go into the folder out/ beside it, and {folder} is {kind}",
                         path=folder, hint="move it away, or give -o in another folder")
    text = starter_design(mesh_path, surface, design_path=out, progress=progress)
    made = not folder.exists()
    try:
        folder.mkdir(exist_ok=True)
    except OSError as e:
        raise output_error(e, folder, "the folder of the design's outputs") from None
    try:
        written = write_design_text(plan, text)
    except BaseException:
        if made:                              # nothing of this run stays behind
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise
    summary = {"design": written, "mesh": str(mesh_path), "out": str(folder)}
    return InitReport(design=written, mesh=str(mesh_path), out_folder=str(folder), summary=summary,
                      text=f"ffd init: wrote {written}\n  next: uncomment a change in it, then `ffd plot {written}` "
                           f"and `ffd deform {written}`")


def _relative(path: Path, folder: Path) -> str:
    """``path`` relative to ``folder`` when they share a folder below ``/``, else absolute."""
    a, b = path.resolve(), folder.resolve()
    if os.path.commonpath([a, b]) == a.anchor:
        return a.as_posix()
    return Path(os.path.relpath(a, b)).as_posix()


def default_design_path(mesh_path) -> Path:
    """``<mesh stem>.yaml`` beside the mesh (the default of ``ffd init -o``)."""
    p = Path(mesh_path)
    return p.with_name(p.stem + ".yaml")


def _change_examples(dim: int, points, chord: float) -> list[tuple[str, str]]:
    """(YAML text of one commented change item, its meaning); an empty text is a comment line."""
    n = points[0]
    bump = _round(0.01 * chord)             # 1 % of the chord, in mesh units
    up = [0.0] + [bump] * (n - 2) + [0.0]
    low = [0.0] + [-bump] * (n - 2) + [0.0]
    if dim == 2:
        return [
            ("- twist: 2", "degrees, the whole airfoil about its trailing edge (nose up +)"),
            ("- twist: {angle: 2, axis: 0.25}", "the same about the quarter chord (chord fraction)"),
            ("- chord: 1.1", "scale factor of the airfoil about its trailing edge"),
            (f"- shape: {{upper: {_flow(up)}, lower: {_flow(low)}}}",
             "thickness-wise moves of the upper/lower control points, mesh units"),
            ("- shape: {random: " + f"{bump:g}" + ", seed: 7}", "random upper/lower moves in [-A, A]"),
        ]
    m = points[1]
    ramp = [round(5.0 * j / (m - 1), 2) for j in range(m)]
    return [
        ("- twist: {tip: 5}", "degrees, linear from 0 at the root to 5 at the tip, nose up +"),
        ("- twist: {root: -1, tip: 3}", "degrees, linear from root to tip"),
        (f"- twist: {_flow(ramp)}", f"degrees per section, root first ({m} sections)"),
        ("- twist: {tip: 5, axis: 0.25}", "the same about the quarter chord (axis: chord fraction)"),
        ("", "twist rotates each section about its trailing edge (axis: 1, the default); the root "
             "stays unless named"),
        ("- span: 1.1", "span scale factor about the root section (chords unchanged)"),
        ("- sweep: 5", "degrees added to the leading-edge sweep"),
        ("- dihedral: 3", "degrees added to the dihedral (tip up +)"),
        ("- chord: {tip: 0.8}", "chord scale factor, linear from 1 at the root; about the TE"),
        (f"- shape: {{upper: {_flow(up)}, lower: {_flow(low)}, sections: all}}",
         "thickness-wise moves per chordwise point (+-1 % chord), mesh units"),
        ("- shape: {random: " + f"{bump:g}" + ", seed: 7}", "random upper/lower moves in [-A, A]"),
    ]
