"""SU2 plumbing shared by the optimisation benchmark (not a benchmark itself: no ``bench_`` prefix).

Finding SU2 (``SU2_RUN``, ``PATH``, then ``../shared/su2/bin`` beside the repository), editing a
config (``KEY= value`` lines), running a program in a folder with its log, reading ``history.csv``,
and the content-hash cache of finished runs: a run's folder is ``<root>/<label>-<hash>`` where the
hash covers the config text, the input files' bytes and the command; the run is finished when its
``result.json`` exists (written last, atomically), so an interrupted run is started again from scratch
and a finished one is reused by the next invocation.
"""

from __future__ import annotations

import contextlib
import csv
import fcntl
import hashlib
import json
import os
import shutil
import subprocess
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
DATA = SHARED / "data" / "su2"
NACA_MESH = DATA / "optimization_euler__steady_naca0012__mesh_NACA0012_inv.su2"
NACA_FFD_MESH = DATA / "optimization_euler__steady_inverse_design__mesh_NACA0012_inv_FFD_v8.su2"
NACA_CFG = DATA / "configs" / "optimization_euler__steady_naca0012__inv_NACA0012_basic.cfg"
SCRATCH = Path(os.environ.get("FFD_OPTBENCH_ROOT", "/work/scratch/optbench"))


def su2_bin() -> Path | None:
    """The folder holding ``SU2_CFD`` (``SU2_RUN``, then ``PATH``, then ``../shared/su2/bin``), or None."""
    candidates = []
    if os.environ.get("SU2_RUN"):
        candidates.append(Path(os.environ["SU2_RUN"]))
    found = shutil.which("SU2_CFD")
    if found:
        candidates.append(Path(found).resolve().parent)
    candidates.append(SHARED / "su2" / "bin")
    for c in candidates:
        if (c / "SU2_CFD").is_file():
            return c
    return None


def su2_env() -> dict:
    """Environment for SU2's programs and scripts (``SU2_RUN``, ``PATH``, ``PYTHONPATH``)."""
    b = su2_bin()
    if b is None:
        raise RuntimeError("SU2 not found: set SU2_RUN or put SU2_CFD on PATH")
    env = dict(os.environ)
    env["SU2_RUN"] = str(b)
    env["PATH"] = f"{b}:{env.get('PATH', '')}"
    env["PYTHONPATH"] = str(b)
    env.setdefault("OMP_NUM_THREADS", "1")
    return env


# ----------------------------------------------------------------------------------------------
# Configs
# ----------------------------------------------------------------------------------------------

def cfg_set(text: str, **keys) -> str:
    """``text`` with each ``KEY= value`` line replaced (or appended when absent); None deletes a key."""
    lines = text.splitlines()
    out, done = [], set()
    for line in lines:
        s = line.strip()
        key = s.split("=", 1)[0].strip() if ("=" in s and not s.startswith("%")) else None
        if key in keys:
            if key not in done and keys[key] is not None:
                out.append(f"{key}= {keys[key]}")
            done.add(key)
            continue
        out.append(line)
    for k, v in keys.items():
        if k not in done and v is not None:
            out.append(f"{k}= {v}")
    return "\n".join(out) + "\n"


def cfg_get(text: str, key: str) -> str | None:
    """The value of ``KEY=`` in a config text (last occurrence), or None."""
    val = None
    for line in text.splitlines():
        s = line.strip()
        if s.startswith("%") or "=" not in s:
            continue
        k, v = s.split("=", 1)
        if k.strip() == key:
            val = v.strip()
    return val


# ----------------------------------------------------------------------------------------------
# Running
# ----------------------------------------------------------------------------------------------

def file_digest(path: Path) -> str:
    """sha256 of a file's bytes (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def case_hash(cfg_text: str, inputs: list[Path], command: list[str]) -> str:
    """Cache key of a run: the config text, the inputs' content and the command line."""
    h = hashlib.sha256()
    h.update(cfg_text.encode())
    for p in inputs:
        h.update(file_digest(Path(p)).encode())
    h.update(" ".join(command).encode())
    return h.hexdigest()[:12]


@contextlib.contextmanager
def solver_slot():
    """One SU2 process of this benchmark at a time per slot: an exclusive lock on
    ``<scratch>/<slot>.lock`` (slot ``FFD_OPTBENCH_SLOT``, default ``su2``: one slot, one process on the
    machine) held for the whole run (waiting for it is not counted in a run's time). Two invocations with
    two slots run two SU2 processes at once (a two-core machine: each run on its own core)."""
    SCRATCH.mkdir(parents=True, exist_ok=True)
    with open(SCRATCH / f"{os.environ.get('FFD_OPTBENCH_SLOT', 'su2')}.lock", "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)
    time.sleep(1.0)          # let a waiting process take the slot before this one asks again


def run(cmd: list[str], cwd: Path, log: str, env: dict | None = None, nice: int = 5,
        timeout: float | None = None) -> tuple[int, float]:
    """Run ``cmd`` in ``cwd`` under ``nice`` in the solver slot, stdout+stderr to ``cwd/log``;
    returns (exit code, wall seconds of the run itself)."""
    full = (["nice", "-n", str(nice)] if nice else []) + [str(c) for c in cmd]
    with solver_slot():
        t0 = time.perf_counter()
        with open(Path(cwd) / log, "w") as f:
            p = subprocess.run(full, cwd=cwd, stdout=f, stderr=subprocess.STDOUT,
                               env=env or su2_env(), timeout=timeout)
        wall = time.perf_counter() - t0
    return p.returncode, wall


def write_json_atomic(path: Path, data: dict) -> None:
    """Write ``data`` as JSON to ``path`` through a temporary file and a rename."""
    tmp = Path(str(path) + ".tmp")
    tmp.write_text(json.dumps(data, indent=1, sort_keys=True))
    os.replace(tmp, path)


def cached_run(root: Path, label: str, cfg_text: str, inputs: list[Path], command: list[str],
               body, force: bool = False, only_cached: bool = False, resume: bool = False) -> dict | None:
    """Reuse ``<root>/<label>-<hash>/result.json`` if present, else run ``body(folder)`` -> dict and store it.

    ``body`` gets a fresh, empty folder; its dict gets ``folder``, ``hash``, ``load_before``,
    ``load_after`` (1-minute load averages) and ``finished`` (UTC) added. ``only_cached``: return
    None instead of running when no finished run has this hash. ``resume``: an unfinished run's folder
    is kept and handed to ``body`` as it is (a command that resumes), instead of being started afresh.
    """
    key = case_hash(cfg_text, inputs, command)
    folder = Path(root) / f"{label}-{key}"
    res = folder / "result.json"
    if res.exists() and not force:
        data = json.loads(res.read_text())
        data["cached"] = True
        return data
    if only_cached:
        return None
    if folder.exists() and (force or not resume):
        shutil.rmtree(folder)
    folder.mkdir(parents=True, exist_ok=True)
    load0 = os.getloadavg()[0]
    data = body(folder)
    data.update(folder=str(folder), hash=key, load_before=load0, load_after=os.getloadavg()[0],
                finished=time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()))
    write_json_atomic(res, data)
    data["cached"] = False
    return data


# ----------------------------------------------------------------------------------------------
# Reading
# ----------------------------------------------------------------------------------------------

def read_history(path: Path) -> list[dict]:
    """Rows of an SU2 ``history.csv`` as dicts of floats, keys without quotes and blanks."""
    with open(path) as f:
        rows = list(csv.reader(f))
    head = [h.strip().strip('"').strip() for h in rows[0]]
    out = []
    for r in rows[1:]:
        if not r:
            continue
        try:
            out.append({h: float(v) for h, v in zip(head, r)})
        except ValueError:
            continue
    return out


def last_history(path: Path) -> dict:
    """The last row of an SU2 ``history.csv``."""
    rows = read_history(path)
    if not rows:
        raise RuntimeError(f"{path}: no rows")
    return rows[-1]
