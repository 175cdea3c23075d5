"""A run's record kept in the repository: the small files that carry its figures and let it go on.

An optimisation run here outlives a sitting and its folder lives under ``out/`` (not in git), so a
machine that starts afresh loses it. ``keep`` copies what the case's reports, the race and ``--resume``
read into ``benchmarks/adodg/records/<name>/`` (committed as the run goes); ``restore`` puts it back
into a run folder so that the reports read it and the run continues.

* **ffd** (``ffd optimize`` folder: ``history.csv`` and ``evals/NNNN/result.json``): ``history.csv``,
  ``best.yaml``, each evaluation's ``result.json`` (its variables, functions, gradients, solves and
  seconds: ``--resume`` reuses every one whose inputs hash matches, so only the unfinished ones are
  solved again) and its flow's ``history.csv``.
* **SU2** (``shape_optimization.py`` folder: ``config.cfg`` and ``DESIGNS/``): the configuration,
  ``box.json``, ``baseline_geometry.json``, ``run.json``, ``history_project.csv``, ``optimizer.log``,
  ``project.pkl`` (SU2's own restart, ``-r``; each design's convergence histories in it cut to their
  last row, :data:`SLIM_PROJECT`, the only row SU2's restart reads), each design's ``config_DSN.cfg``,
  its flow's ``history_direct.csv`` (whether the flow converged) and its adjoints' gradient files
  (``of_grad*.csv``). SU2's restart copies the files its state names (meshes, solutions) from each
  design folder before it answers from its cache, so ``restore`` writes an empty file for each one
  recorded in ``record.json`` but not kept: those are never read for a design whose functions and
  gradients are known (a new design's flow starts from ``RESTART_SOL= NO`` and its own deformed mesh).
  A design cut short (its flow, or an adjoint it had begun, unfinished) would read them, so
  ``restore`` takes it out of ``project.pkl`` with its folder: SU2 makes it again from its start
  (its deformation, flow and adjoints), as ffd's ``--resume`` solves such an evaluation's flow again.

Files over :data:`PACK_ABOVE` bytes are kept gzipped (``NAME.gz``; ``restore`` unpacks them), and a
file still over :data:`MAX_BYTES` is left out (and listed in ``record.json``), so no mesh or solution
enters git by a pattern's accident. ::

    python -m benchmarks.adodg.record keep out/adodg3h/case3 case3_h0_ffd
    python -m benchmarks.adodg.record restore case3_h0_ffd out/adodg3h/case3
    python -m benchmarks.adodg.record status        # a line on each record
"""

from __future__ import annotations

import argparse
import gzip
import json
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from benchmarks.adodg.su2_side import su2_env

RECORDS = Path(__file__).resolve().parent / "records"
MAX_BYTES = 2_000_000       # no file of a record is larger (after packing)
PACK_ABOVE = 200_000        # files larger than this are kept gzipped (flow histories, SU2's project.pkl)

FFD_FILES = ("history.csv", "best.yaml", "evals/*/result.json", "evals/*/history.csv")
SU2_FILES = ("config.cfg", "box.json", "baseline_geometry.json", "run.json", "history_project.csv",
             "optimizer.log", "project.pkl", "DESIGNS/DSN_*/config_DSN.cfg",
             "DESIGNS/DSN_*/DIRECT/history_direct.csv", "DESIGNS/DSN_*/ADJOINT_*/of_grad*.csv")


class RecordError(Exception):
    """A folder that is not a run, or a record that does not exist (the message names it)."""


@dataclass(frozen=True)
class Kept:
    """What ``keep`` did: the files copied (relative paths), those left out as too large, the bytes."""

    kind: str
    files: tuple[str, ...]
    too_large: tuple[str, ...]
    bytes: int


def kind_of(run: Path) -> str:
    """``"ffd"`` for an ``ffd optimize`` folder, ``"su2"`` for a ``shape_optimization.py`` one."""
    run = Path(run)
    if (run / "evals").is_dir() or (run / "history.csv").is_file():
        return "ffd"
    if (run / "config.cfg").is_file() and ((run / "DESIGNS").is_dir() or (run / "project.pkl").is_file()):
        return "su2"
    raise RecordError(f"{run}: neither an `ffd optimize` run folder (history.csv, evals/) nor an SU2 "
                      "shape_optimization.py one (config.cfg, DESIGNS/)")


def selected(run: Path, patterns: tuple[str, ...]) -> list[Path]:
    """The files of ``run`` matching ``patterns`` (relative paths, sorted, each once)."""
    found = {p.relative_to(run) for pat in patterns for p in run.glob(pat) if p.is_file()}
    return sorted(found)


def steady_copy(src: Path, dst: Path, tries: int = 5, packed: bool = False) -> bool:
    """Copy ``src`` to ``dst`` (gzip-compressed when ``packed``, with no time stamp, so the same bytes
    give the same file) again until ``src`` did not change while it was copied (a running run rewrites
    ``project.pkl`` and ``history.csv`` after each design). False when it changed at every try (a
    running solve's history): ``dst`` is then removed."""
    for _ in range(tries):
        before = src.stat()
        if packed:
            with open(src, "rb") as fin, open(dst, "wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as fout:
                shutil.copyfileobj(fin, fout)
        else:
            shutil.copyfile(src, dst)
        after = src.stat()
        if (before.st_mtime_ns, before.st_size) == (after.st_mtime_ns, after.st_size):
            return True
    dst.unlink(missing_ok=True)
    return False


def keep(run: Path, record: Path) -> Kept:
    """Write the record of ``run`` into ``record`` afresh (built beside it, then put in its place, so a
    record never mixes two keeps): the record files, each over :data:`PACK_ABOVE` bytes gzipped
    (``NAME.gz``), and ``record.json``: the kind, the files kept, those packed, those too large even
    packed, and for SU2 every other file of the design folders (the names ``restore`` writes empty)."""
    run, record = Path(run), Path(record)
    kind = kind_of(run)
    files = selected(run, FFD_FILES if kind == "ffd" else SU2_FILES)
    fresh = record.with_name(record.name + ".new")
    shutil.rmtree(fresh, ignore_errors=True)
    try:
        out = _build(run, fresh, kind, files)
    except BaseException:
        shutil.rmtree(fresh, ignore_errors=True)          # nothing half-written is left beside the record
        raise
    shutil.rmtree(record, ignore_errors=True)
    fresh.rename(record)
    return out


def _build(run: Path, fresh: Path, kind: str, files: list[Path]) -> Kept:
    """The record of ``run`` written into ``fresh`` (see :func:`keep`)."""
    kept, packed, large, changing, total = [], [], [], [], 0
    for rel in files:
        src = run / rel
        if kind == "su2" and str(rel) == "project.pkl":
            src = fresh / "slim" / "project.pkl"
            src.parent.mkdir(parents=True, exist_ok=True)
            if not steady_copy(run / rel, src):
                raise RecordError(f"{run / rel}: kept changing while it was copied; keep again later")
            slim_project(src.parent)
        pack = src.stat().st_size > PACK_ABOVE
        dst = fresh / (str(rel) + ".gz" if pack else rel)
        dst.parent.mkdir(parents=True, exist_ok=True)
        if not steady_copy(src, dst, packed=pack):
            changing.append(str(rel))                   # a solve still writing it: its design is unfinished
            continue
        size = dst.stat().st_size
        if size > MAX_BYTES:
            dst.unlink()
            large.append(str(rel))
            continue
        kept.append(str(rel))
        if pack:
            packed.append(str(rel))
        total += size
    placeholders = []
    if kind == "su2":
        names = set(kept)
        placeholders = sorted(str(p.relative_to(run)) for p in (run / "DESIGNS").rglob("*")
                              if p.is_file() and p.suffix != ".pkl" and str(p.relative_to(run)) not in names)
    meta = {"kind": kind, "source": str(run), "files": kept, "packed": packed, "too_large": large,
            "changing": changing, "placeholders": placeholders}
    fresh.mkdir(parents=True, exist_ok=True)
    shutil.rmtree(fresh / "slim", ignore_errors=True)
    (fresh / "record.json").write_text(json.dumps(meta, indent=1) + "\n")
    return Kept(kind=kind, files=tuple(kept), too_large=tuple(large), bytes=total)


#: Run by SU2's own Python in a folder holding a copy of ``project.pkl``: each design's convergence
#: histories (``state.HISTORY``, every iteration of its flow and adjoints, most of the file's size)
#: cut to their last row, which is all SU2's ``Project.compile_results`` reads of them.
SLIM_PROJECT = """
import SU2
p = SU2.io.load_data("project.pkl")
for d in p.designs:
    for kind in d.state.HISTORY:
        for key in d.state.HISTORY[kind]:
            d.state.HISTORY[kind][key] = d.state.HISTORY[kind][key][-1:]
SU2.io.save_data("project.pkl", p)
"""


def _su2_python(code: str, folder: Path) -> subprocess.CompletedProcess:
    """Run ``code`` with SU2's Python package in ``folder``; RecordError when SU2 is not found."""
    try:
        env = su2_env()
    except RuntimeError as exc:
        raise RecordError(f"{exc} (its scripts read project.pkl)") from None
    return subprocess.run([sys.executable, "-c", code], cwd=folder, env=env, capture_output=True, text=True)


def slim_project(folder: Path) -> None:
    """:data:`SLIM_PROJECT` on ``folder/project.pkl`` (SU2's scripts needed)."""
    out = _su2_python(SLIM_PROJECT, folder)
    if out.returncode != 0:
        raise RecordError(f"{Path(folder) / 'project.pkl'}: SU2's scripts could not read it: "
                          f"{out.stderr.strip().splitlines()[-1] if out.stderr.strip() else out.returncode}")


#: Run by SU2's own Python (its package, ``SU2_RUN`` set) in the run folder: removes the design folders
#: ``project.pkl`` does not know (begun after its last save), and drops its last design when that was
#: cut short (no functions yet, or an ``ADJOINT_<F>`` folder whose gradient SU2's state does not hold)
#: with its folder; prints each folder removed.
DROP_UNFINISHED = """
import glob, os, shutil, SU2
p = SU2.io.load_data("project.pkl")
known = {os.path.normpath(d.folder) for d in p.designs}
for folder in sorted(glob.glob(os.path.join("DESIGNS", "DSN_*"))):
    if os.path.normpath(folder) not in known:
        shutil.rmtree(folder)
        print(folder)
if p.designs:
    d = p.designs[-1]
    names = os.listdir(d.folder) if os.path.isdir(d.folder) else []
    begun = [a[len("ADJOINT_"):] for a in names if a.startswith("ADJOINT_")]
    if not d.state.FUNCTIONS or any(f not in d.state.GRADIENTS for f in begun):
        p.designs.pop()
        SU2.io.save_data("project.pkl", p)
        shutil.rmtree(d.folder, ignore_errors=True)
        print(d.folder)
"""


def drop_unfinished(run: Path) -> str | None:
    """Take a cut-short last design out of an SU2 run's ``project.pkl`` (see :data:`DROP_UNFINISHED`);
    the folders removed (one per line), or None."""
    out = _su2_python(DROP_UNFINISHED, run)
    if out.returncode != 0:
        raise RecordError(f"{Path(run) / 'project.pkl'}: SU2's scripts could not read it: "
                          f"{out.stderr.strip().splitlines()[-1] if out.stderr.strip() else out.returncode}")
    return out.stdout.strip() or None


@dataclass(frozen=True)
class Restored:
    """What ``restore`` did: the files written, and the SU2 design folder dropped as cut short (or None)."""

    written: int
    dropped: str | None = None


def restore(record: Path, run: Path, drop: bool = True) -> Restored:
    """Copy a record back into ``run`` (created); files the run already has are left as they are. For
    SU2, the design files the record did not keep are written empty (SU2's restart copies them, reads
    none), and with ``drop`` a design cut short is taken out (:func:`drop_unfinished`)."""
    record, run = Path(record), Path(run)
    meta_path = record / "record.json"
    if not meta_path.is_file():
        raise RecordError(f"{meta_path}: no such file (a folder written by `record keep`)")
    meta = json.loads(meta_path.read_text())
    written = 0
    packed = set(meta.get("packed", []))
    for rel in meta["files"]:
        src = record / (rel + ".gz" if rel in packed else rel)
        if not src.is_file():
            raise RecordError(f"{src}: listed in record.json but missing")
        if not (run / rel).exists():
            (run / rel).parent.mkdir(parents=True, exist_ok=True)
            if rel in packed:
                with gzip.open(src, "rb") as fin, open(run / rel, "wb") as fout:
                    shutil.copyfileobj(fin, fout)
            else:
                shutil.copyfile(src, run / rel)
            written += 1
    for rel in meta.get("placeholders", []):
        if not (run / rel).exists():
            (run / rel).parent.mkdir(parents=True, exist_ok=True)
            (run / rel).touch()
            written += 1
    dropped = None
    if drop and meta["kind"] == "su2" and (run / "project.pkl").is_file():
        dropped = drop_unfinished(run)
    return Restored(written=written, dropped=dropped)


def status(record: Path) -> str:
    """One line on a record: its kind and source, designs, flow and adjoint solves, finished or not."""
    record = Path(record)
    meta = json.loads((record / "record.json").read_text())
    files = meta["files"]
    if meta["kind"] == "ffd":
        results = [json.loads((record / f).read_text()) for f in files if f.endswith("result.json")]
        flows = sum(r["solves"]["flow"] for r in results)
        adjoints = sum(r["solves"]["adjoint"] for r in results)
        designs, done = f"{len(results)} evaluations", "best.yaml" in files
    else:
        flows = sum(1 for f in files if f.endswith("DIRECT/history_direct.csv"))
        adjoints = sum(1 for f in files if "/ADJOINT_" in f and Path(f).name.startswith("of_grad"))
        dsn = {f.split("/")[1] for f in files if f.startswith("DESIGNS/")}
        designs, done = f"{len(dsn)} designs", "run.json" in files
    return (f"{record.name}: {meta['kind']} run of {meta['source']}, {designs}, {flows} flow + {adjoints} "
            f"adjoint solves, {'finished' if done else 'not finished (restore, then --resume)'}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.adodg.record", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    k = sub.add_parser("keep", help="copy a run's record files into benchmarks/adodg/records/NAME")
    k.add_argument("run", type=Path)
    k.add_argument("name")
    r = sub.add_parser("restore", help="put a record back into a run folder (then --resume, or the reports)")
    r.add_argument("name")
    r.add_argument("run", type=Path)
    sub.add_parser("status", help="a line on each record: designs, solves, finished or not")
    args = ap.parse_args(argv)
    try:
        if args.command == "status":
            for rec in sorted(p.parent for p in RECORDS.glob("*/record.json")):
                print(status(rec))
        elif args.command == "keep":
            if not Path(args.run).is_dir():
                raise RecordError(f"{args.run}: no such folder")
            out = keep(args.run, RECORDS / args.name)
            print(f"{RECORDS / args.name}: {out.kind} run, {len(out.files)} files, {out.bytes / 1e6:.2f} MB"
                  + (f"; left out as larger than {MAX_BYTES:,} bytes: {', '.join(out.too_large)}"
                     if out.too_large else ""))
        else:
            out = restore(RECORDS / args.name, args.run)
            print(f"{args.run}: {out.written} files written from {RECORDS / args.name}"
                  + (f"; {out.dropped} was cut short: SU2 makes it again from its start" if out.dropped else ""))
    except RecordError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
