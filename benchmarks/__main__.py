"""Run the benchmarks: ``python -m benchmarks [--quick] [--only NAME ...]``.

Finds every ``benchmarks/bench_*.py``, calls its ``run(quick)`` and prints one Markdown table per
module with the columns case / measured / target / pyGeo reference (a module whose rows have other
keys defines ``summary(rows)`` mapping them to those columns; its full rows follow as a "details"
table). At the end, one table of every case that has a target, with whether it is met.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def discover() -> list[str]:
    """Names (``core``, ``io``, ...) of the ``bench_*`` modules next to this file, sorted."""
    return sorted(m.name[len("bench_"):] for m in pkgutil.iter_modules([str(HERE)])
                  if m.name.startswith("bench_"))


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        if value == 0.0:
            return "0"
        if abs(value) >= 1e4 or abs(value) < 1e-3:
            return f"{value:.2e}"
        return f"{value:.3g}" if abs(value) < 100 else f"{value:.0f}"
    return str(value)


def markdown_table(rows: list[dict]) -> str:
    """A Markdown table of ``rows`` (dicts); columns are the keys in first-seen order."""
    if not rows:
        return "(no rows)"
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for r in rows:
        lines.append("| " + " | ".join(_cell(r.get(c)).replace("|", "\\|") for c in cols) + " |")
    return "\n".join(lines)


SUMMARY_COLUMNS = ("case", "measured", "target", "pyGeo reference")


def summary_rows(module, rows: list[dict]) -> tuple[list[dict], bool]:
    """(rows in the summary columns, whether they differ from ``rows``)."""
    fn = getattr(module, "summary", None)
    if fn is None:
        return rows, False
    return fn(rows), True


def main(argv=None) -> int:
    names = discover()
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes only (a smoke run, about 2 minutes)")
    ap.add_argument("--only", action="append", metavar="NAME", choices=names,
                    help=f"run only this module (repeatable): {', '.join(names)}")
    args = ap.parse_args(argv)
    failed = 0
    targets: list[dict] = []
    t_all = time.perf_counter()
    for name in args.only or names:
        module = importlib.import_module(f"benchmarks.bench_{name}")
        title = getattr(module, "TITLE", name)
        print(f"## {title}\n", flush=True)
        t0 = time.perf_counter()
        try:
            rows = module.run(quick=args.quick)
            table, has_details = summary_rows(module, rows)
        except Exception as exc:  # one broken benchmark must not hide the others' tables
            failed += 1
            print(f"benchmark {name} failed: {type(exc).__name__}: {exc}\n", flush=True)
            continue
        print(markdown_table(table))
        if has_details:
            print("\nDetails:\n\n" + markdown_table(rows))
        notes = getattr(module, "NOTES", "")
        if notes:
            print("\n" + notes.strip())
        print(f"\n({name}: {time.perf_counter() - t0:.1f} s)\n", flush=True)
        targets += [{"module": name, **{k: r.get(k) for k in ("case", "measured", "target")},
                     "met": r.get("met")} for r in table if r.get("target")]
    if targets:
        print("## Targets\n")
        print(markdown_table(targets))
        print()
    print(f"(all: {time.perf_counter() - t_all:.0f} s)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
