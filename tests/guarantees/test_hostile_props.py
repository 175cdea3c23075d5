"""Hostile conditions beyond single bad inputs: random valid designs, interrupts, concurrent runs.

- Property: every valid design on a small volume wing either writes a mesh that reads back with the
  same markers, element counts and the computed coordinates, or is refused by the quality gate
  (exit 3) — never a crash. Checked in-process (library calls) for speed, and through the CLI.
- Atomic writes: ``ffd deform`` interrupted by SIGINT at many moments leaves either no output or a
  complete one (identical to an uninterrupted run), exit status 130, and no ``.part`` file.
- Concurrency: two ``ffd deform`` runs on one mesh started together, with no cache yet, both succeed
  with identical outputs and leave one valid cache that a third run reuses.
"""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import file_hash, popen_ffd, run_ffd
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from wingcase import write_design, write_volume_wing

from ffdcli.io.atomic import interrupts_outside_compilers

N, M = 6, 8     # lattice points chordwise and spanwise of write_design's default box (6, 8, 2)


# ----------------------------------------------------------------------------------------------
# Random valid designs
# ----------------------------------------------------------------------------------------------

def small(lo, hi):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False).map(lambda x: round(x, 6))


CHANGE = st.one_of(
    st.builds(lambda t: {"twist": {"tip": t}}, small(-20, 20)),
    st.builds(lambda r, t: {"twist": {"root": r, "tip": t}}, small(-5, 5), small(-20, 20)),
    st.builds(lambda v: {"twist": v}, st.lists(small(-10, 10), min_size=M, max_size=M)),
    st.builds(lambda s: {"span": s}, small(0.6, 1.5)),
    st.builds(lambda d: {"sweep": d}, small(-30, 30)),
    st.builds(lambda d: {"dihedral": d}, small(-20, 20)),
    st.builds(lambda o: {"sweep": {"offsets": [0.0] + o}}, st.lists(small(-0.2, 0.2), min_size=M - 1,
                                                                    max_size=M - 1)),
    st.builds(lambda c: {"chord": {"tip": c}}, small(0.3, 2.0)),
    st.builds(lambda c: {"chord": c}, st.lists(small(0.5, 1.5), min_size=M, max_size=M)),
    st.builds(lambda u, lo: {"shape": {"upper": u, "lower": lo}},
              st.lists(small(-0.03, 0.03), min_size=N, max_size=N),
              st.lists(small(-0.03, 0.03), min_size=N, max_size=N)),
    st.builds(lambda a, s: {"shape": {"random": a, "seed": s}}, small(0, 0.05), st.integers(0, 2**31)),
)
DESIGN = st.lists(CHANGE, min_size=1, max_size=3)


@pytest.fixture(scope="module")
def wing(tmp_path_factory):
    d = tmp_path_factory.mktemp("props")
    mesh = write_volume_wing(d)
    return d, mesh, file_hash(mesh)


def _counts(mesh):
    return ({name: [(b.type, len(b)) for b in blocks] for name, blocks in mesh.markers.items()},
            [(b.type, len(b)) for b in mesh.cells])


def _check_written(path: Path, original, points_expected):
    from ffdcli.io.formats import read_mesh

    back = read_mesh(path)
    assert list(back.markers) == list(original.markers)
    assert _counts(back) == _counts(original)
    assert back.points.shape == original.points.shape
    assert np.all(np.isfinite(back.points))
    # SU2 ASCII keeps 17 significant digits here; 1e-12 of the wing size is far above that and far
    # below any displacement a change makes.
    assert np.allclose(back.points, points_expected, rtol=0, atol=1e-12 * np.ptp(original.points))


OUTCOMES: list[bool] = []       # quality verdicts of the drawn designs (both kinds must occur)


@settings(max_examples=25, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(changes=DESIGN)
def test_random_valid_designs_write_or_are_refused(wing, changes):
    from ffdcli.app.deformation import deform
    from ffdcli.app.run import load_run
    from ffdcli.app.write import write_outputs
    from ffdcli.design import load_design
    from ffdcli.errors import QualityError

    folder, mesh_path, mesh_hash = wing
    design_file = write_design(folder, mesh_path, changes, name="prop.yaml")
    out = folder / "out_prop.su2"
    out.unlink(missing_ok=True)
    design = load_design(design_file)
    run = load_run(design)
    try:
        result = deform(run)
    except QualityError:          # overflow-sized values: refused, nothing to write
        return
    q = result.quality
    assert q is not None
    OUTCOMES.append(q.ok)
    if not q.ok:                  # the CLI refuses it with exit 3 and writes nothing
        return
    written = write_outputs(run, result)
    assert Path(written["mesh"]) == out
    _check_written(out, run.prep.mesh, result.points)
    assert file_hash(mesh_path) == mesh_hash
    assert not list(folder.glob("*.part*"))


def test_random_designs_cover_both_outcomes():
    """The property above saw designs that were written and designs that the gate refused (runs after
    it, in file order; skipped when run alone)."""
    if not OUTCOMES:
        pytest.skip("run together with test_random_valid_designs_write_or_are_refused")
    assert any(OUTCOMES), OUTCOMES
    assert not all(OUTCOMES), OUTCOMES


@pytest.mark.slow
@pytest.mark.parametrize("changes,code", [
    ([{"twist": {"tip": 7.5}}, {"sweep": 12}, {"shape": {"random": 0.01, "seed": 3}}], 0),
    ([{"twist": {"tip": 90}}, {"chord": {"tip": 0.3}}], 3),
], ids=["valid", "gate"])
def test_cli_design_writes_or_is_refused(wing, changes, code):
    """The same property through the command line: exit 0 with a readable mesh, or exit 3 and nothing."""
    from ffdcli.io.formats import read_mesh

    folder, mesh_path, mesh_hash = wing
    name = f"cli_{len(changes)}_{abs(hash(json.dumps(changes))) % 10**6}.yaml"
    design_file = write_design(folder, mesh_path, changes, name=name)
    out = folder / f"out_{Path(name).stem}.su2"
    proc = run_ffd("deform", design_file.name, "--json", cwd=folder)
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.returncode == code, proc.stderr
    if proc.returncode == 3:
        assert not out.exists()
        assert "quality" in proc.stderr
    else:
        _check_written(out, read_mesh(mesh_path), read_mesh(out).points)
    assert file_hash(mesh_path) == mesh_hash


# ----------------------------------------------------------------------------------------------
# SIGINT during a run: no partial output
# ----------------------------------------------------------------------------------------------

def _popen_ffd(*args, cwd):
    return popen_ffd(*args, cwd=cwd)


@pytest.fixture(scope="module")
def big_wing(tmp_path_factory):
    """A volume wing big enough that writing it takes a noticeable time (~100k nodes), with no warp."""
    from ffdcli.io.formats import write_mesh
    from ffdcli.testing.wings import Planform, extruded_wing_mesh

    d = tmp_path_factory.mktemp("sigint")
    mesh = extruded_wing_mesh(Planform(), n_around=121, n_radial=33, n_span=26)
    path = d / "big.su2"
    write_mesh(mesh, path)
    write_design(d, path, [{"twist": {"tip": 3}}], name="big.yaml", volume={"method": "none"})
    proc = run_ffd("deform", "big.yaml", "-q", "--force", cwd=d)   # builds the cache (and compiles kernels)
    assert proc.returncode == 0, proc.stderr
    t0 = time.perf_counter()     # the duration of a cached run: the interrupts below are fractions of it
    proc = run_ffd("deform", "big.yaml", "-q", "--force", cwd=d)
    assert proc.returncode == 0, proc.stderr
    seconds = time.perf_counter() - t0
    ref = d / "ref.su2"
    (d / "out_big.su2").rename(ref)
    return d, path, file_hash(path), file_hash(ref), seconds


@pytest.mark.slow
def test_sigint_leaves_no_partial_output(big_wing):
    folder, mesh_path, mesh_hash, ref_hash, seconds = big_wing
    out = folder / "out_big.su2"
    codes = []
    # Interrupt at fractions of a full (cached) run's duration, so that some land in the write.
    for frac in (0.5, 0.9, 0.7, 0.6, 0.4):     # a loaded machine can stretch the reference run past several
        out.unlink(missing_ok=True)
        (folder / "out_big_lattice.vtk").unlink(missing_ok=True)
        p = _popen_ffd("deform", "big.yaml", "-q", "--force", cwd=folder)
        time.sleep(frac * seconds * 0.9)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=120)
        codes.append(p.returncode)
        # -SIGINT: the interrupt came as the run ended (the interpreter's exit restores the default
        # handler); never -SIGSEGV (an interrupt inside numba's kernel loading, held since 2026-12-02)
        assert p.returncode in (0, 130, -signal.SIGINT), (p.returncode, err)
        if p.returncode == 130:
            assert "interrupted; nothing was written" in err and "Traceback" not in err, err
        if out.exists():           # complete: bit for bit the uninterrupted result
            assert file_hash(out) == ref_hash, (frac, p.returncode)
        else:
            assert p.returncode != 0
        assert not list(folder.glob("*.part*")), list(folder.glob("*"))
        assert file_hash(mesh_path) == mesh_hash
    # Interrupts that certainly land inside a write: wait until the temporary file appears.
    inside_write = 0
    for _ in range(6):
        out.unlink(missing_ok=True)
        p = _popen_ffd("deform", "big.yaml", "-q", "--force", cwd=folder)
        while p.poll() is None and not list(folder.glob(".out_big.su2.*part*")):
            time.sleep(0.002)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=120)
        codes.append(p.returncode)
        assert p.returncode in (0, 130), err
        if out.exists():             # the write finished between the poll and the signal: complete
            assert file_hash(out) == ref_hash, err
        else:
            assert p.returncode == 130 and "Traceback" not in err, err
            inside_write += 1
        assert not list(folder.glob("*.part*")), list(folder.glob("*"))
        if inside_write == 2:
            break
    # The cache survived the interrupts: a later run reuses it and gives the same mesh.
    out.unlink(missing_ok=True)
    proc = run_ffd("deform", "big.yaml", "--json", "--force", cwd=folder)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["from_cache"] is True
    assert file_hash(out) == ref_hash
    if 130 not in codes or not inside_write:     # the timing could not be produced (every run ended first)
        pytest.skip(f"the machine is too loaded to time an interrupt inside a run (exit codes {codes}, "
                    f"{inside_write} inside a write)")


# ----------------------------------------------------------------------------------------------
# Two runs at once on one mesh, no cache yet
# ----------------------------------------------------------------------------------------------

@pytest.mark.slow
def test_concurrent_runs_share_the_cache(tmp_path):
    mesh = write_volume_wing(tmp_path)
    mesh_hash = file_hash(mesh)
    for name in ("a.yaml", "b.yaml"):
        write_design(tmp_path, mesh, [{"twist": {"tip": 4}}, {"sweep": 5}], name=name)
    assert not list(tmp_path.glob("*.ffdcache.npz"))
    procs = [_popen_ffd("deform", name, "--json", cwd=tmp_path) for name in ("a.yaml", "b.yaml")]
    results = [p.communicate(timeout=300) for p in procs]
    for p, (_, err) in zip(procs, results):
        assert p.returncode == 0, err
        assert "Traceback" not in err
    assert file_hash(tmp_path / "out_a.su2") == file_hash(tmp_path / "out_b.su2")
    caches = list(tmp_path.glob("*.ffdcache.npz"))
    assert len(caches) == 1, caches
    assert not list(tmp_path.glob("*.part*"))
    with np.load(caches[0]) as z:            # a complete, readable cache file
        assert "params" in z.files and json.loads(bytes(z["header"]).decode())["key"]
    write_design(tmp_path, mesh, [{"twist": {"tip": 4}}, {"sweep": 5}], name="c.yaml")
    proc = run_ffd("deform", "c.yaml", "--json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["from_cache"] is True
    assert file_hash(tmp_path / "out_c.su2") == file_hash(tmp_path / "out_a.su2")
    assert file_hash(mesh) == mesh_hash



def test_an_interrupt_inside_numba_is_held_until_it_returns():
    """Ctrl-C while numba/llvmlite code is on the stack is held (raising it there crashed the
    interpreter) and raised once that code has returned; elsewhere at once."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "setitimer"):
        pytest.skip("signals are handled in the main thread of a POSIX process")
    fake = {"__file__": os.path.join(os.sep, "x", "numba", "core", "fake.py")}
    exec(compile("def inside(f):\n    return f()\n", fake["__file__"], "exec"), fake)   # a frame "in numba"
    seen = []

    def busy():
        os.kill(os.getpid(), signal.SIGINT)
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < 0.2:      # the interrupt arrives here, "in numba": held
            pass
        seen.append("returned")

    with interrupts_outside_compilers():
        with pytest.raises(KeyboardInterrupt):
            fake["inside"](busy)
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < 2.0:  # raised within a poll of leaving numba
                pass
        assert seen == ["returned"]
        with pytest.raises(KeyboardInterrupt):     # outside numba: at once
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(2.0)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
