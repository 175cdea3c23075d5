"""The outputs of one run: planned before any work, written together at the end.

A command (or a Python caller) builds one :class:`OutputPlan` from what it was given (the design
file's ``output:``, ``-o``, ``--lattice``, ``--plot``, ...) before it reads the mesh. Planning checks
every output at once, so that a mistake costs no minutes of work:

- the name is not empty and has the suffix its kind needs (:data:`KINDS`: a mesh ``.su2``/``.cgns``/
  ``.vtu``/``.vtk``, a lattice ``.vtk``, a picture ``.png``);
- nothing that exists there is other than a regular file (a FIFO, a device, a folder, a symlink loop);
- no output is an input of the run (the mesh, the design file, a sensitivity file, ...) or another
  output of the same run;
- the folder exists (a default folder such as ``out/`` beside the design file is created) and can be
  written, and the name fits the file system.

:meth:`OutputPlan.write` then writes every output to a temporary file beside its destination and,
only when all are complete, renames them into place one after the other: the run's outputs appear
together or not at all. On any failure (a full disk, a name too long, Ctrl-C, SIGTERM, SIGHUP) every
temporary file is removed and an OS error becomes one ``ffd: error:`` line naming the file.

One more kind of output: :func:`register` an :class:`OutputKind`, add it to the plan, and give
:meth:`OutputPlan.write` a writer for it.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

from ffdcli.errors import FfdError, InputError, note_committed
from ffdcli.io.atomic import (
    check_not_input,
    check_writable,
    existing_kind,
    keep_mode,
    make_temp,
    output_error,
    replace_folder,
    signals_deferred,
    signals_raise,
)
from ffdcli.io.formats import FOLDER_FORMAT, extensions, format_of, mismatch_message
from ffdcli.io.inputs import polymesh_folder_of


@dataclass(frozen=True)
class OutputKind:
    """One kind of output file: its name in a plan, what it is (for messages), the suffixes it may
    have (None: any) and the message when it has another."""

    name: str
    what: str
    suffixes: tuple[str, ...] | None = None
    wrong_suffix: str = ""


#: The kinds of output, by name (one home for the suffix rules).
KINDS: dict[str, OutputKind] = {}


def register(kind: OutputKind) -> OutputKind:
    """Add (or replace) an output kind."""
    KINDS[kind.name] = kind
    return kind


register(OutputKind("mesh", "the deformed mesh", tuple(extensions())))
register(OutputKind("lattice", "the lattice", (".vtk",),
                    "the lattice is written as legacy VTK: give it a .vtk name"))
register(OutputKind("plot", "the picture", (".png",), "pictures are written as PNG: give it a .png name"))
register(OutputKind("plot_3d", "the 3D picture", (".png",), "pictures are written as PNG: give it a .png name"))
register(OutputKind("plot3d", "the Plot3D lattice"))
register(OutputKind("surface_file", "the SU2 surface file"))
register(OutputKind("grad", "the gradient"))
register(OutputKind("jacobian", "the Jacobian"))
register(OutputKind("design", "the design file", (".yaml", ".yml"),
                    "design files are YAML: give it a .yaml name"))
register(OutputKind("history", "the optimisation history", (".csv",), "the history is CSV: give it a .csv name"))


def kind_spec(kind: str) -> OutputKind:
    """The :class:`OutputKind` of ``kind``; ``<kind>.<name>`` is one of several outputs of a kind, e.g.
    ``lattice.htail``, the lattice of component ``htail`` (same rules, named in messages). The table
    :data:`KINDS` is filled once, at import: nothing is registered while a run plans its outputs."""
    if kind in KINDS:
        return KINDS[kind]
    base, _, name = kind.partition(".")
    if base in KINDS and name:
        spec = KINDS[base]
        return replace(spec, name=kind, what=f"{spec.what} of {name}")
    raise KeyError(f"unknown output kind {kind!r}")


@dataclass(frozen=True)
class Output:
    """One planned output file."""

    kind: str
    path: Path

    @property
    def what(self) -> str:
        return kind_spec(self.kind).what


@dataclass(frozen=True)
class OutputPlan:
    """Every output of one run, checked (see the module). Build it with :func:`plan_outputs` (or
    :func:`plan_deform`, :func:`plan_plot`), then :meth:`write` them together."""

    outputs: tuple[Output, ...]
    inputs: tuple[Path, ...] = field(default=())

    def __contains__(self, kind: str) -> bool:
        return any(o.kind == kind for o in self.outputs)

    def path(self, kind: str) -> Path | None:
        """The path of output ``kind``, None when the run does not write it."""
        return next((o.path for o in self.outputs if o.kind == kind), None)

    def paths(self) -> dict[str, str]:
        return {o.kind: str(o.path) for o in self.outputs}

    def write(self, writers: Mapping[str, Callable[[Path], object]]) -> dict[str, str]:
        """Write the outputs: ``writers[kind](tmp_path)`` writes output ``kind`` to a temporary file;
        a writer that returns ``False`` wrote nothing (that output is skipped). When every writer has
        finished, the files are renamed into place (signals held meanwhile). Returns {kind: path} of
        what was written. On any exception every temporary file is removed and no output appears;
        an OSError becomes an :class:`~ffdcli.errors.FfdError` naming the file."""
        unknown = [k for k in writers if k not in self]
        if unknown:
            raise ValueError(f"no planned output of kind {', '.join(unknown)}")
        temps: list[tuple[Output, Path]] = []
        written: dict[str, str] = {}
        current = None
        try:
            with signals_raise():
                for out in self.outputs:
                    if out.kind not in writers:
                        continue
                    current = out
                    _check_still_regular(out)
                    tmp = make_temp(out.path)
                    temps.append((out, tmp))
                    try:
                        done = writers[out.kind](tmp)
                    except FfdError as e:     # a writer's message names the file the user knows
                        if e.path is not None and Path(e.path) == tmp:
                            e.path = str(out.path)
                            e.args = (e.format(),)
                        raise
                    if done is False:
                        temps.pop()
                        tmp.unlink(missing_ok=True)
                with signals_deferred():
                    for out, tmp in temps:
                        current = out
                        if tmp.is_dir():          # a folder output (an OpenFOAM case)
                            replace_folder(tmp, out.path)
                        else:
                            keep_mode(out.path, tmp)
                            os.replace(tmp, out.path)
                        written[out.kind] = str(out.path)
                    # complete under their names: a signal held above, or any later, says so
                    note_committed(written.values())
        except OSError as e:
            _remove(temps)
            raise output_error(e, current.path if current else "", current.what if current else "the output") \
                from None
        except BaseException:
            _remove(temps)
            raise
        return written


def _remove(temps) -> None:
    for _, tmp in temps:
        with contextlib.suppress(OSError):
            if tmp.is_dir() and not tmp.is_symlink():
                shutil.rmtree(tmp)
            else:
                tmp.unlink()


def _check_still_regular(out: Output) -> None:
    if out.kind == "mesh" and format_of(out.path) == FOLDER_FORMAT:
        check_folder_output(out.path)
        return
    kind = existing_kind(out.path)
    if kind not in (None, "regular file"):
        raise InputError(f"the output path exists and is {kind}; outputs are written only as regular files",
                         path=out.path, hint="choose another output path")


def check_output(kind: str, path: str | Path, *, inputs: Iterable[str | Path | None] = (),
                 others: Iterable[Output] = (), create_folder: bool = False, option: str | None = None) -> Path:
    """Check one output path of kind ``kind`` (see the module); returns it as a Path.

    ``inputs``: files of the run that must never be overwritten (the first is the mesh);
    ``others``: outputs already planned; ``create_folder``: a default location whose folder is made;
    ``option``: the command-line option or design key that gave the path (for messages)."""
    spec = kind_spec(kind)
    if str(path) == "":
        raise InputError(f"the file name of {spec.what} is empty", key=option, hint="give a file name")
    p = Path(path)
    inputs = tuple(inputs)
    check_not_input(p, inputs)
    for other in others:
        if _same(p, other.path):
            raise InputError(f"{spec.what} would overwrite {other.what} of this run; give them different "
                             "names", path=p)
    if kind == "mesh":
        fmt = format_of(p, key=option)
        try:
            src = format_of(inputs[0]) if inputs and inputs[0] is not None else None   # the mesh: first input
        except InputError:
            src = None
        if src is not None and FOLDER_FORMAT in (fmt, src) and fmt != src:
            raise InputError(mismatch_message(src, fmt), path=p, key=option)
        if fmt == FOLDER_FORMAT:
            return check_folder_output(p, inputs=inputs, create_folder=create_folder)
    elif spec.suffixes is not None and p.suffix.lower() not in spec.suffixes:
        raise InputError(spec.wrong_suffix or f"{spec.what} needs one of the suffixes {', '.join(spec.suffixes)}",
                         path=p)
    if create_folder and not p.parent.exists():
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise output_error(e, p.parent, "the output folder") from None
    return check_writable(p, inputs=tuple(inputs))


def check_folder_output(p: Path, *, inputs: tuple = (), create_folder: bool = False) -> Path:
    """Check an output that is a folder (an OpenFOAM case): not an input, not a folder holding the
    input, its parent writable; an existing folder there must be an OpenFOAM case (it is replaced
    whole, so anything else is refused)."""
    check_not_input(p, inputs)
    for src in inputs[:1]:
        if src is not None and _inside(Path(src), p):
            raise InputError("the output folder holds the input mesh; choose another output path", path=p)
    if create_folder and not p.parent.exists():
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise output_error(e, p.parent, "the output folder") from None
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"the output folder {str(parent)!r} does not exist", path=p, hint="create it first")
    if not os.access(parent, os.W_OK):
        raise InputError(f"the output folder {str(parent)!r} is not writable", path=p)
    kind = existing_kind(p)
    if kind == "folder" and polymesh_folder_of(p) is None:
        raise InputError("the output path is a folder that is not an OpenFOAM case; ffd replaces only a case "
                         "folder (with constant/polyMesh) at an output path", path=p, hint="choose another output path")
    if kind not in (None, "folder"):
        raise InputError(f"the output path exists and is {kind}; an OpenFOAM case is written as a folder",
                         path=p, hint="choose another output path")
    return p


def check_output_folder(folder: str | Path, *, key: str | None = None, design=None) -> Path:
    """Check a folder that a run writes into (made when it first writes there), creating nothing:
    :class:`InputError` (exit 2) naming the folder and why, before any work, when it exists and is not a
    folder (a file, a FIFO, ...), a part of its path is not a folder, or it (or the folder it would be made
    in) is on a read-only file system or cannot be written. ``key``: the design key that gave it
    (``optimize.folder``); ``design``: the loaded design, whose file and line the message names."""
    p = Path(folder)

    def fail(message: str, hint: str | None = None):
        text = f"{p}: {message}" + (f" ({hint})" if hint else "")
        if design is not None and key is not None:
            raise design.error(text, key)
        raise InputError(message, path=p, key=key, hint=hint)

    probe, missing = p, []
    while True:
        kind = existing_kind(probe)
        if kind is not None:
            break
        if probe.parent == probe:
            fail("no part of the path exists")
        missing.append(probe.name)
        probe = probe.parent
    if kind != "folder":
        if probe == p:
            fail(f"is {'a file' if kind == 'regular file' else kind}, not a folder",
                 "give a folder name, or move the file away")
        fail(f"{probe} is {'a file' if kind == 'regular file' else kind}, not a folder, so the folder cannot "
             "be made", "give a folder name")
    if _read_only(probe):
        fail(f"{'is' if probe == p else f'would be made in {probe}, which is'} on a read-only file system",
             "choose a folder on a writable file system")
    if not os.access(probe, os.W_OK | os.X_OK):
        fail(f"{'cannot be written' if probe == p else f'cannot be made: {probe} cannot be written'} "
             "(permission denied)", "choose a writable folder")
    return p


def _read_only(folder: Path) -> bool:
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def plan_in_folder(folder: str | Path, requested: Iterable[tuple[str, str | Path]], *,
                   inputs: Iterable[str | Path | None] = (), key: str | None = None, design=None) -> OutputPlan:
    """The plan of outputs ``requested`` (``(kind, path)``) of a run that writes into ``folder`` and makes
    it when missing (``ffd optimize``'s folder): the folder checked (:func:`check_output_folder`), and
    every output checked as :func:`plan_outputs` does (never an input of the run, under any name) when
    the folder exists; nothing is created."""
    p = check_output_folder(folder, key=key, design=design)
    items = list(requested)
    if existing_kind(p) == "folder":
        return plan_outputs([(kind, path, False, key) for kind, path in items], inputs=inputs)
    ins = tuple(Path(x) for x in inputs if x is not None)
    outs: list[Output] = []
    for kind, path in items:                    # the folder does not exist yet: no input lies in it
        check_not_input(Path(path), ins)
        outs.append(Output(kind, Path(path)))
    return OutputPlan(outputs=tuple(outs), inputs=ins)


def _inside(inner: Path, outer: Path) -> bool:
    """True when ``inner`` is ``outer`` or lies inside it (resolved paths)."""
    try:
        a, b = inner.resolve(), outer.resolve()
    except (OSError, RuntimeError):
        return False
    return a == b or b in a.parents


def _same(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and os.path.samefile(a, b))
    except (OSError, RuntimeError):
        return False


def plan_outputs(requested: Iterable[tuple], *, inputs: Iterable[str | Path | None] = ()) -> OutputPlan:
    """Check and plan outputs. ``requested``: ``(kind, path)`` or ``(kind, path, create_folder)`` or
    ``(kind, path, create_folder, option)``; a ``None`` path is not written. ``inputs``: the run's
    input files, the mesh first (never overwritten)."""
    ins = tuple(Path(p) for p in inputs if p is not None)
    outs: list[Output] = []
    for item in requested:
        kind, path, create, option = (*item, *(False, None)[len(item) - 2:])
        if path is None:
            continue
        p = check_output(kind, path, inputs=ins, others=outs, create_folder=bool(create), option=option)
        outs.append(Output(kind, p))
    return OutputPlan(outputs=tuple(outs), inputs=ins)


# ----------------------------------------------------------------------------------------------
# The plans of the commands that write a design's results
# ----------------------------------------------------------------------------------------------

def carried_name(mesh_path: str | Path, kind: str) -> Path:
    """The name that an output mesh ``-o out/crm_t5.su2`` gives to the other outputs of its run:
    ``out/crm_t5_lattice.vtk`` (lattice), ``out/crm_t5.png`` (plot), ``out/crm_t5_3d.png`` (plot_3d)."""
    p = Path(mesh_path)
    return p.with_name(p.stem + {"lattice": "_lattice.vtk", "plot": ".png", "plot_3d": "_3d.png"}[kind])


def plan_deform(design, *, mesh: str | Path | None = None, lattice: str | Path | None = None,
                plot: bool = False, extra: Iterable[tuple] = (), inputs: Iterable = ()) -> OutputPlan:
    """The outputs of ``ffd deform`` of a loaded design (:class:`ffdcli.design.Design`).

    ``mesh`` (``-o``) replaces ``output.mesh`` and carries the names of the lattice and the picture
    (:func:`carried_name`) unless ``lattice`` (``--lattice``) is given; without ``-o`` they are the
    design file's ``output:`` (defaults ``out/<design stem>...`` beside the design file, whose folder
    is created). The picture is written only with ``plot`` (``--plot``: a ``--set`` loop pays for no
    picture it did not ask for), at ``output.plot`` when the file names it, with its 3D view
    ``<picture stem>_3d.png`` beside it (3D designs, when pyvista can render). ``extra``: more
    ``(kind, path, ...)`` outputs (e.g. a surface file); ``inputs``: more input files of the run."""
    given = set((design.data or {}).get("output") or {})
    want_plot = plot
    if mesh is not None:
        mesh_item = ("mesh", mesh, False, "-o")
        lat = lattice if lattice is not None else (None if str(mesh) == "" else carried_name(mesh, "lattice"))
        lat_item = ("lattice", lat, False, "--lattice" if lattice is not None else None)
        png = (carried_name(mesh, "plot") if str(mesh) else None) if want_plot else None
        png_item = ("plot", png, False, None)
    else:
        mesh_item = ("mesh", design.output["mesh"], "mesh" not in given, "output.mesh")
        if lattice is not None:
            lat_item = ("lattice", lattice, False, "--lattice")
        else:
            lat_item = ("lattice", design.output["lattice"], "lattice" not in given, "output.lattice")
        if not want_plot:
            png_item = ("plot", None)
        elif "plot" in given:
            png_item = ("plot", design.output["plot"], False, "output.plot")
        else:
            png_item = ("plot", carried_name(design.output["mesh"], "plot"), "mesh" not in given, None)
    png = png_item[1] if len(png_item) > 1 else None
    view_item = ("plot_3d", carried_name(png, "plot_3d") if png is not None else None)
    lat_items = [lat_item]
    if getattr(design, "components", None) and len(lat_item) > 1 and lat_item[1] is not None:
        # several components: one lattice file per component, named after it
        lat_items = [(lattice_kind(c.name), component_lattice_path(lat_item[1], c.name), *lat_item[2:])
                     for c in design.components]
    return plan_outputs([mesh_item, *lat_items, png_item, view_item, *extra],
                        inputs=(design.mesh, design.path, *_box_inputs(design), *inputs))


def plan_plot(design, output: str | Path | None = None, *, view3d: bool = False) -> OutputPlan:
    """The outputs of ``ffd plot``: the picture (``-o``, else ``output.plot``, default
    ``out/<design stem>.png``) and, with ``view3d``, ``<picture stem>_3d.png`` beside it."""
    given = set((design.data or {}).get("output") or {})
    if output is not None:
        item = ("plot", output, False, "-o")
    else:
        item = ("plot", design.output["plot"], "plot" not in given, "output.plot")
    png = item[1]
    view = ("plot_3d", carried_name(png, "plot_3d") if view3d and str(png) else None)
    return plan_outputs([item, view], inputs=(design.mesh, design.path, *_box_inputs(design)))


def _box_inputs(design) -> tuple:
    f = getattr(getattr(design, "box", None), "file", None)
    return (f,) if f else ()


__all__ = ["KINDS", "Output", "OutputKind", "kind_spec", "OutputPlan", "carried_name", "check_output",
           "check_output_folder", "plan_deform", "plan_in_folder", "plan_outputs", "plan_plot", "register"]


def component_lattice_path(lattice_path, name: str) -> Path:
    """The lattice file of component ``name`` of a design with several: ``<stem>_<name>.vtk`` beside
    the design's lattice file (``out/a_lattice.vtk`` -> ``out/a_lattice_wing.vtk``)."""
    p = Path(lattice_path)
    return p.with_name(f"{p.stem}_{name}{p.suffix}")


def lattice_kind(name: str) -> str:
    """The output kind (:mod:`ffdcli.io.outputs`) of component ``name``'s lattice file: ``lattice.<name>``,
    a legacy VTK like the single lattice (:func:`ffdcli.io.outputs.kind_spec`)."""
    return f"lattice.{name}"
