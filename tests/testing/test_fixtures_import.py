"""ffdcli.testing ships in the wheel as public fixtures: every module imports without gmsh."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import ffdcli.testing

MODULES = sorted(p.stem for p in Path(ffdcli.testing.__file__).parent.glob("*.py") if p.stem != "__init__")


def test_every_fixture_imports_without_gmsh():
    # sys.modules["gmsh"] = None makes "import gmsh" raise ImportError, as on a machine without it
    code = ("import sys; sys.modules['gmsh'] = None\n"
            + "".join(f"import ffdcli.testing.{m}\n" for m in MODULES)
            + "from ffdcli.testing.gmsh_wings import CASES, fluid_tets\n"
            + "try:\n    fluid_tets({}, (0, 0, 0), (1, 1, 1), symmetry_axis=2, h_solid=1, h_edge=1, h_far=1)\n"
            + "except ImportError:\n    print('gmsh needed only here')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=Path(__file__).parent)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "gmsh needed only here"
    assert {"naca", "planform", "wings", "ogrid", "cells", "gmsh_wings", "prisms"} <= set(MODULES)
