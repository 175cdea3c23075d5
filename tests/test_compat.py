"""Old import paths keep working for one release: the same module object, with a DeprecationWarning."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

from ffdcli import _compat


@pytest.mark.parametrize("old", sorted(_compat.MOVED))
def test_old_path_is_the_new_module_and_warns(old):
    code = (f"import importlib, warnings\nwarnings.simplefilter('error', DeprecationWarning)\n"
            f"try:\n    importlib.import_module('ffdcli.{old}')\nexcept DeprecationWarning as e:\n"
            f"    print(e)\nelse:\n    print('no warning')\n")
    said = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert f"ffdcli.{old} has moved to ffdcli.{_compat.MOVED[old]}" in said


def test_old_submodule_path_is_the_same_object():
    with pytest.warns(DeprecationWarning, match="ffdcli.io.formats.su2"):
        old = importlib.import_module("ffdcli.formats.su2")
    assert old is importlib.import_module("ffdcli.io.formats.su2")


def test_new_name_of_unmoved_modules_is_none():
    assert _compat.new_name("ffdcli.errors") is None
    assert _compat.new_name("ffdcli.changesets") is None
    assert _compat.new_name("ffdcli.changes.Twist") == "ffdcli.parameterization.changes.Twist"


@pytest.mark.parametrize("face", ["mesh", "lattice", "box", "parallel", "quality", "constraints"])
def test_old_module_names_that_are_packages_offer_the_old_names(face):
    pkg = importlib.import_module(f"ffdcli.{face}")
    assert pkg.__all__ and all(hasattr(pkg, n) for n in pkg.__all__)
