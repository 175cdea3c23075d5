"""Shared test helpers: where the real data is, and how to run the command line."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from ffdcli.optimize.solvers.base import find_program

REPO = Path(__file__).resolve().parents[1]

# OpenMDAO writes each problem's reports into <script>_out/ under its work folder, by default the
# current one (the repository when pytest runs there): a folder of its own for the session instead.
os.environ.setdefault("OPENMDAO_WORKDIR", tempfile.mkdtemp(prefix="ffd-openmdao-"))
SAMPLES = REPO / "samples"

# The test folders mirror the package (tests/io/ tests ffdcli/io/, ...). A test reuses another
# folder's fixtures by module name (``from test_su2 import HEX2``): every folder is on the path.
for _folder in sorted(Path(__file__).resolve().parent.iterdir()):
    if _folder.is_dir() and _folder.name[0] not in "._" and str(_folder) not in sys.path:
        sys.path.append(str(_folder))
# tests/guarantees/hostile.py: the guarantee tests' helpers and workspaces (a plugin of those modules)
pytest.register_assert_rewrite("hostile")


def _find_shared_data() -> Path | None:
    env = os.environ.get("FFD_SHARED_DATA")
    candidates = [Path(env)] if env else []
    candidates += [REPO.parent / "shared" / "data", Path("/work/shared/data")]
    for c in candidates:
        if c.is_dir():
            return c
    return None


SHARED_DATA = _find_shared_data()


def su2_folder() -> Path | None:
    """The folder of SU2_CFD as ``ffd optimize`` finds it (``$SU2_RUN``, PATH), else the shared SU2 build
    beside the repository (``../shared/su2/bin``); None when there is none (the SU2 tests skip)."""
    extra = (SHARED_DATA.parent / "su2" / "bin",) if SHARED_DATA is not None else ()
    found = find_program("SU2_CFD", "SU2_RUN", extra)
    return None if found is None else found.parent


SU2_MISSING = "SU2_CFD not found ($SU2_RUN, PATH, ../shared/su2/bin): SU2 is not installed"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data (real meshes from public projects); the test is skipped when it is absent."""
    if SHARED_DATA is None:
        pytest.skip("../shared/data is not present (set FFD_SHARED_DATA to point at it)")
    return SHARED_DATA


def shared_file(rel: str) -> Path:
    """A file of ../shared/data, or skip the calling test."""
    if SHARED_DATA is None or not (SHARED_DATA / rel).exists():
        pytest.skip(f"shared data file {rel} is not present")
    return SHARED_DATA / rel


def run_ffd(*args, cwd=None, input=None, env=None, timeout=600) -> subprocess.CompletedProcess:
    """Run ``ffd ARGS`` in a fresh interpreter; returns the CompletedProcess (text mode)."""
    e = dict(os.environ)
    e["PYTHONPATH"] = str(REPO) + os.pathsep + e.get("PYTHONPATH", "")
    if env:
        e.update(env)
    return subprocess.run([sys.executable, "-m", "ffdcli", *map(str, args)], cwd=cwd, input=input,
                          capture_output=True, text=True, env=e, timeout=timeout)


def _default_signals() -> None:
    """In the child: SIGINT, SIGTERM and SIGHUP back to their defaults. A test suite started under
    ``nohup`` or in the background of a script inherits them ignored, and so would every ffd it starts
    (Python keeps an inherited ignored SIGINT), so an interrupt test could never interrupt."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)


def popen_ffd(*args, cwd=None) -> subprocess.Popen:
    """Start ``ffd ARGS`` in a fresh interpreter with the default signal dispositions (to be signalled)."""
    e = dict(os.environ)
    e["PYTHONPATH"] = str(REPO) + os.pathsep + e.get("PYTHONPATH", "")
    return subprocess.Popen([sys.executable, "-m", "ffdcli", *map(str, args)], cwd=cwd, env=e,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_default_signals)


def file_hash(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def assert_clean_failure(proc: subprocess.CompletedProcess, code: int = 2, *must_contain: str):
    """A bad-input failure: the exit code, one message line naming the problem, no traceback."""
    assert proc.returncode == code, (proc.returncode, proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr, proc.stderr
    assert "ffd: error:" in proc.stderr, proc.stderr
    for text in must_contain:
        assert text in proc.stderr, (text, proc.stderr)


@pytest.fixture
def default_sigint():
    """SIGINT as Python's default (KeyboardInterrupt) for the test, restored after: a pytest-xdist
    worker runs with SIGINT ignored, and ffd leaves an ignored signal ignored (as a program started in
    the background must), so a test that sends itself Ctrl-C needs the default back."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)
