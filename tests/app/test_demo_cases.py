"""make demo deforms the design files of configs/ that are deformations, and each one can run."""

from __future__ import annotations

import yaml

from ffdcli.app.demo import REPO, demo_cases


def test_demo_cases_are_the_deformations_whose_meshes_are_there():
    cases = demo_cases(REPO / "configs")
    names = {c.stem for c in cases}
    assert {"rect_twist_linear", "crm_twist_tip", "wing_tail_fin", "wing_body"} <= names
    assert "naca0012_s1223" not in names                     # the fit's input, run by the fit case
    for c in sorted((REPO / "configs").glob("*.yaml")):
        spec = yaml.safe_load(c.read_text())
        if "optimize" in spec:                               # ffd optimize's inputs are not demo cases
            assert c.stem not in names
    for c in cases:                                          # a missing mesh stops make demo (exit 2)
        spec = yaml.safe_load(c.read_text())
        meshes = [spec["mesh"]] if "mesh" in spec else []
        assert all((c.parent / m).exists() for m in meshes), c.name
