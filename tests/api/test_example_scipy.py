"""examples/scipy_inverse_twist.py runs and recovers the hidden twist (the scipy.optimize example)."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
from conftest import REPO
from wingcase import write_design, write_surface_wing

EXAMPLE = REPO / "examples" / "scipy_inverse_twist.py"


def _run(*args, cwd):
    proc = subprocess.run([sys.executable, str(EXAMPLE), *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return float(re.search(r"max twist error (\S+) degrees", proc.stdout).group(1))


def test_scipy_example_on_the_bundled_wing(tmp_path):
    assert _run(cwd=tmp_path) < 1e-5


@pytest.mark.parametrize("planform", [dict(sections="xz", le_sweep_deg=25.0, taper=0.5),
                                      dict(sections="yz", dihedral_deg=4.0)])
def test_scipy_example_on_other_wings(tmp_path, planform):
    mesh = write_surface_wing(tmp_path, **planform)
    design = write_design(tmp_path, mesh, [{"twist": [0.0] * 6}], points=(5, 6, 2))
    assert _run(design, cwd=tmp_path) < 1e-5
