"""The design file: schema, validation messages (key path + line), --set, build_changes, configs/."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import yaml
from conftest import REPO, run_ffd

from ffdcli.design import apply_overrides, build_changes, design_schema, load_design
from ffdcli.errors import InputError
from ffdcli.parameterization.changes import Chord, Dihedral, Shape, Span, Sweep, Twist, design_variables

CONFIGS = sorted((REPO / "configs").glob("*.yaml"))


def write(tmp_path: Path, text: str, name="design.yaml") -> Path:
    p = tmp_path / name
    p.write_text(textwrap.dedent(text).lstrip("\n"))
    (tmp_path / "wing.su2").write_text("NDIME= 3\n")     # load_design only checks that it exists
    return p


BASE = """
mesh: wing.su2
surface: wing
box:
  points: [6, 8, 2]
changes:
  - twist: [0, 1, 2, 3, 4, 5, 6, 7]
  - span: 1.1
"""


# ------------------------------------------------------------------------------------- configs/

def test_the_schema_is_a_valid_draft_2020_12_schema():
    jsonschema.Draft202012Validator.check_schema(design_schema())


def test_there_is_a_config_for_every_paper_case():
    names = {p.stem for p in CONFIGS}
    assert {"rect_twist_linear", "rect_twist_sections", "rect_span", "rect_dihedral_up", "rect_dihedral_down",
            "rect_sweep", "rect_shape_all", "rect_shape_random", "crm_twist_tip", "crm_span",
            "crm_dihedral_up", "crm_dihedral_down", "naca0012_s1223"} <= names


@pytest.mark.parametrize("config", CONFIGS, ids=lambda p: p.stem)
def test_every_config_validates_loads_and_builds(config):
    jsonschema.Draft202012Validator(design_schema()).validate(yaml.safe_load(config.read_text()))
    data = yaml.safe_load(config.read_text())
    generated = "optimize" in data and "out/" in data["mesh"]
    # the ONERA M6 optimisation reads a mesh made by its generator into out/ (docs/optimize.md)
    design = load_design(config, check_files=(REPO / "samples").is_dir() and not generated)
    assert design.mesh.parent == (REPO / ("out" if generated else "samples")).resolve()
    assert design.output["mesh"].parent == (REPO / "out").resolve()
    from ffdcli.design import changes_from_spec
    from ffdcli.parameterization.components import specs_of

    for spec in specs_of(design):            # a design with components: each one's box and changes
        pts = spec.box.points
        n, m, l, dim = (pts[0], pts[1], pts[2], 3) if len(pts) == 3 else (pts[0], 1, pts[1], 2)
        # flaps and slats read the box (their hinge, the knots they add): built by the flap tests
        items = [c for c in spec.changes_spec if next(iter(c)) not in ("flap", "slat")]
        if not items:
            continue
        changes = changes_from_spec(items, n, m, l, dim)
        names, values = design_variables(changes)
        assert len(names) == len(values) > 0 and np.all(np.isfinite(values))


def test_config_values_are_the_papers():
    d = load_design(REPO / "configs" / "rect_twist_sections.yaml", check_files=False)
    (tw,) = build_changes(d, 6, 8, 2, 3)
    np.testing.assert_array_equal(tw.values, [0, 10, 10, 12, 15, 15, 16, -22])
    d = load_design(REPO / "configs" / "crm_twist_tip.yaml", check_files=False)
    (tw,) = build_changes(d, 6, 8, 2, 3)
    assert tw.variables() == [("twist.tip", 15.0)] and tw.values[0] == 0.0
    d = load_design(REPO / "configs" / "naca0012_s1223.yaml", check_files=False)
    assert d.box.points == (6, 5)


# ----------------------------------------------------------------------------------------- load

def test_load_resolves_paths_and_defaults(tmp_path):
    d = load_design(write(tmp_path, BASE, "case.yaml"))
    assert d.mesh == (tmp_path / "wing.su2").resolve()
    assert d.surface == ["wing"]
    assert d.box.points == (6, 8, 2) and d.box.degree is None
    assert d.volume == {"method": "idw"}
    assert d.output["mesh"] == (tmp_path / "out" / "case.su2").resolve()
    assert d.output["lattice"] == (tmp_path / "out" / "case_lattice.vtk").resolve()
    assert d.changes_spec == [{"twist": [0, 1, 2, 3, 4, 5, 6, 7]}, {"span": 1.1}]
    changes = build_changes(d, 6, 8, 2, 3)
    assert isinstance(changes[0], Twist) and isinstance(changes[1], Span)
    assert design_variables(changes)[0][-2:] == ["c0.twist[7]", "c1.span"]


def test_missing_mesh_and_design_files(tmp_path):
    p = write(tmp_path, BASE.replace("wing.su2", "nowhere.su2"))
    with pytest.raises(InputError) as e:
        load_design(p)
    assert e.value.key == "mesh" and e.value.line == 1 and "not found" in str(e.value)
    with pytest.raises(InputError, match="design file not found"):
        load_design(tmp_path / "none.yaml")


def test_output_may_not_be_the_input_mesh(tmp_path):
    p = write(tmp_path, BASE + "output:\n  mesh: wing.su2\n")
    with pytest.raises(InputError, match="never overwritten") as e:
        load_design(p)
    assert e.value.key == "output.mesh" and e.value.line == 9


# each case: (YAML, key path, line, words in the message). Line numbers count from 1 in the text.
BAD = [
    ("mesh: wing.su2\nmseh: x\n", "mseh", 2, "unknown key 'mseh'"),
    ("mesh: wing.su2\nchanges:\n  - span: 1.1\n  - twsit: [1]\n", "changes[1].twsit", 4, "unknown change"),
    ("mesh: wing.su2\nchanges:\n  - {twist: [1], span: 1.1}\n", "changes[0]", 3, "exactly one key"),
    ("mesh: wing.su2\nchanges:\n  - {}\n", "changes[0]", 3, "exactly one key"),
    ("mesh: wing.su2\nchanges:\n  - twist: abc\n", "changes[0].twist", 3, "expected degrees"),
    ("mesh: wing.su2\nchanges:\n  - twist:\n      tip: abc\n", "changes[0].twist.tip", 4, "a number"),
    ("mesh: wing.su2\nchanges:\n  - twist: {root: 1}\n", "changes[0].twist", 3, "missing key 'tip'"),
    ("mesh: wing.su2\nchanges:\n  - span: 0\n", "changes[0].span", 3, "greater than 0"),
    ("mesh: wing.su2\nchanges:\n  - span: -1.1\n", "changes[0].span", 3, "greater than 0"),
    ("mesh: wing.su2\nchanges:\n  - chord: {tip: -0.5}\n", "changes[0].chord.tip", 3, "greater than 0"),
    ("mesh: wing.su2\nchanges:\n  - chord: [1, 0, 1]\n", "changes[0].chord[1]", 3, "greater than 0"),
    ("mesh: wing.su2\nchanges:\n  - span: .nan\n", "changes[0].span", 3, "finite"),
    ("mesh: wing.su2\nchanges:\n  - twist:\n    - 0\n    - .inf\n", "changes[0].twist[1]", 5, "finite"),
    ("mesh: wing.su2\nchanges:\n  - sweep: {offset: [0, 1]}\n", "changes[0].sweep.offset", 3, "unknown key"),
    ("mesh: wing.su2\nchanges:\n  - shape: {random: 0.01, upper: [1]}\n", "changes[0].shape.upper", 3,
     "random shape"),
    ("mesh: wing.su2\nchanges:\n  - shape: {sections: all}\n", "changes[0].shape", 3, "upper"),
    ("mesh: wing.su2\nchanges:\n  - shape: {upper: [1], sections: some}\n", "changes[0].shape.sections", 3,
     "all, or a list"),
    ("mesh: wing.su2\nchanges:\n  - shape: {random: 0.01, seed: 1.5}\n", "changes[0].shape.seed", 3,
     "an integer"),
    ("mesh: wing.su2\nbox:\n  points: [6, 8, 2, 3]\n", "box.points", 3, "at most 3"),
    ("mesh: wing.su2\nbox:\n  points: [6, 1, 2]\n", "box.points[1]", 3, "at least 2"),
    ("mesh: wing.su2\nbox:\n  points: [6, 8, 2]\n  degree: [3, 3, 3]\n", "box.degree[2]", 4,
     "at least 4 points"),
    ("mesh: wing.su2\nbox:\n  points: [6, 8, 2]\n  degree: [3, 3]\n", "box.degree", 4, "has 2 values"),
    ("mesh: wing.su2\nbox:\n  sections: xx\n", "box.sections", 3, "must be one of"),
    ("mesh: wing.su2\nbox:\n  margin: -0.1\n", "box.margin", 3, "at least 0"),
    ("mesh: wing.su2\nvolume:\n  method: rbf\n", "volume.method", 3, "idw, none"),
    ("mesh: wing.su2\nvolume:\n  nmethod: idw\n", "volume.nmethod", 3, "unknown key"),
    ("mesh: wing.su2\noutput:\n  mesh: 3\n", "output.mesh", 3, "expected text"),
    ("mesh: wing.su2\nsurface: [wing, 3]\n", "surface[1]", 2, "expected text"),
    ("surface: wing\n", None, None, "missing key 'mesh'"),
    ("mesh: wing.su2\nchanges:\n  twist: [1]\n", "changes", 2, "expected a list"),
    ("- mesh: wing.su2\n", None, None, "is a mapping"),
    ("mesh: wing.su2\nbox:\n  points: [6, 8, 2]\n  points: [6, 8, 2]\n", "box.points", 4, "written twice"),
    ("mesh: wing.su2\nchanges:\n  - twist: [1, 2\n  - span: 2\n", None, 4, "not valid YAML"),
]


@pytest.mark.parametrize("text,key,line,words", BAD, ids=[b[3] + f"@{b[1]}" for b in BAD])
def test_bad_input_names_the_key_path_and_the_line(tmp_path, text, key, line, words):
    p = write(tmp_path, text)
    with pytest.raises(InputError) as e:
        load_design(p)
    err = e.value
    assert words in err.message, err.message
    assert err.key == key, (err.key, err.message)
    assert err.line == line, (err.line, err.message)
    assert err.path == str(p)
    assert "\n" not in str(err)


# ------------------------------------------------------------------------------ build_changes

BUILD_BAD = [
    ("  - twist: [0, 1, 2]\n", 3, "changes[0].twist", "3 values but the box has 8 sections"),
    ("  - twist: 5\n", 3, "changes[0].twist", "in 3D twist takes a list"),
    ("  - chord: 0.5\n", 3, "changes[0].chord", "in 3D chord takes a list"),
    ("  - span: 1.1\n  - sweep: {offsets: [0, 1]}\n", 3, "changes[1].sweep.offsets", "8 sections"),
    ("  - shape: {upper: [0, 1, 2, 3, 4]}\n", 3, "changes[0].shape.upper", "6 chordwise points"),
    ("  - shape:\n      lower: [0, 1, 2, 3, 4, 5]\n      sections: [0, 9]\n", 3,
     "changes[0].shape.sections[1]", "section 9 does not exist"),
    ("  - span: 1.1\n", 2, "changes[0].span", "not defined for a 2D"),
    ("  - dihedral: 3\n", 2, "changes[0].dihedral", "not defined for a 2D"),
    ("  - twist: [1]\n", 2, "changes[0].twist", "in 2D twist takes one number"),
    ("  - chord: {tip: 0.5}\n", 2, "changes[0].chord", "in 2D chord takes one number"),
]


@pytest.mark.parametrize("changes,dim,key,words", BUILD_BAD, ids=[b[3] for b in BUILD_BAD])
def test_build_changes_checks_against_the_lattice(tmp_path, changes, dim, key, words):
    points = "[6, 8, 2]" if dim == 3 else "[6, 5]"
    text = f"mesh: wing.su2\nbox:\n  points: {points}\nchanges:\n{changes}"
    d = load_design(write(tmp_path, text))
    with pytest.raises(InputError) as e:
        build_changes(d, 6, 8 if dim == 3 else 1, 2 if dim == 3 else 5, dim)
    assert words in e.value.message and e.value.key == key
    # the line of the key (or of its closest parent written in the file)
    lines = text.splitlines()
    leaf = key.split(".")[-1].split("[")[0]
    assert leaf in lines[e.value.line - 1], (e.value.line, lines)


def test_build_changes_kinds_forms_and_2d(tmp_path):
    text = """
    mesh: wing.su2
    box: {points: [6, 8, 2]}
    changes:
      - twist: {root: -2, tip: 3}
      - chord: {tip: 0.6}
      - sweep: 5
      - dihedral: {offsets: [0, 0, 0, 0, 0, 0, 0, 0.1]}
      - shape: {upper: [0, 1, 2, 3, 4, 5], sections: [1, 2]}
    """
    d = load_design(write(tmp_path, text))
    tw, ch, sw, di, sh = build_changes(d, 6, 8, 2, 3)
    assert isinstance(ch, Chord) and ch.values[0] == 1.0 and ch.values[-1] == pytest.approx(0.6)
    assert isinstance(sw, Sweep) and sw.delta == 5.0
    assert isinstance(di, Dihedral) and di.variables()[-1] == ("dihedral.offsets[7]", 0.1)
    assert isinstance(sh, Shape) and sh.sections == (1, 2) and sh.lower is None
    names = design_variables([tw, ch, sw, di, sh])[0]
    assert names[:4] == ["c0.twist.root", "c0.twist.tip", "c1.chord.tip", "c2.sweep"]
    d2 = load_design(write(tmp_path, "mesh: wing.su2\nbox: {points: [6, 5]}\nchanges:\n  - twist: 4\n"
                                     "  - chord: 0.9\n  - shape: {upper: [0, 1, 2, 3, 4, 5]}\n", "a.yaml"))
    tw2, ch2, _ = build_changes(d2, 6, 1, 5, 2)
    assert tw2.variables() == [("twist", 4.0)] and ch2.variables() == [("chord", 0.9)]


def test_random_shape_is_reproducible_from_the_seed(tmp_path):
    d = load_design(write(tmp_path, "mesh: wing.su2\nchanges:\n  - shape: {random: 0.015, seed: 7}\n"))
    (a,) = build_changes(d, 6, 8, 2, 3)
    (b,) = build_changes(d, 6, 8, 2, 3)
    up, lo = np.random.default_rng(7).uniform(-0.015, 0.015, size=(2, 6, 8))
    np.testing.assert_array_equal(a.upper, up)
    np.testing.assert_array_equal(a.lower, lo)
    np.testing.assert_array_equal(a.upper, b.upper)
    assert np.abs(a.upper).max() <= 0.015 and a.size == 2 * 6 * 8


# ------------------------------------------------------------------------------------- --set

TIP = "mesh: wing.su2\nbox:\n  points: [6, 8, 2]\nchanges:\n  - twist: {tip: 15}\n  - span: 1.1\n"


def test_set_changes_existing_values_and_adds_known_output_volume_box_keys(tmp_path):
    p = write(tmp_path, TIP)
    d = load_design(p, ["changes.0.twist.tip=12", "changes.1.span=1.25", "box.margin=0.05",
                        "output.mesh=out/x.su2", "volume.method=none", "box.points=[6, 4, 2]"])
    assert d.changes_spec == [{"twist": {"tip": 12}}, {"span": 1.25}]
    assert d.box.margin == 0.05 and d.box.points == (6, 4, 2)
    assert d.output["mesh"] == (tmp_path / "out" / "x.su2").resolve()
    assert d.volume["method"] == "none"
    d = load_design(p, ["changes.0.twist=[0, 1, 2, 3, 4, 5, 6, 7]"])
    assert d.changes_spec[0] == {"twist": [0, 1, 2, 3, 4, 5, 6, 7]}


@pytest.mark.parametrize("item,words", [
    ("changes.0.twist.tpi=3", "no key 'changes[0].twist.tpi'"),
    ("changes.0.twist.root=3", "no key 'changes[0].twist.root'"),
    ("changes.5.span=1", "has 2 items"),
    ("changes.x.span=1", "is a list"),
    ("meshh=a.su2", "no key 'meshh'"),
    ("volume.foo=1", "no key 'volume.foo'"),
    ("changes.1.span.x=1", "is a value"),
    ("changes.0.twist.tip", "expected KEY=VALUE"),
    ("changes.0.twist.tip=[1, 2", "not a YAML"),
])
def test_set_rejects_keys_that_do_not_exist(tmp_path, item, words):
    with pytest.raises(InputError, match=words.replace("[", r"\[").replace("]", r"\]")):
        load_design(write(tmp_path, TIP), [item])


def test_set_values_are_validated_like_the_file(tmp_path):
    with pytest.raises(InputError) as e:
        load_design(write(tmp_path, TIP), ["changes.1.span=-1"])
    assert e.value.key == "changes[1].span" and e.value.line == 6
    with pytest.raises(InputError) as e:
        load_design(write(tmp_path, TIP), ["changes.0.twist.tip=abc"])
    assert e.value.key == "changes[0].twist.tip"


def test_apply_overrides_does_not_modify_its_input():
    data = {"mesh": "a.su2", "changes": [{"span": 1.1}]}
    out = apply_overrides(data, ["changes.0.span=2"])
    assert data["changes"][0]["span"] == 1.1 and out["changes"][0]["span"] == 2


# -------------------------------------------------------------------------------------- CLI

def test_ffd_schema_prints_the_schema():
    proc = run_ffd("schema")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout) == design_schema()
    proc = run_ffd("schema", "--json")
    assert proc.returncode == 0 and json.loads(proc.stdout) == design_schema()


def test_the_schema_is_assembled_from_the_registered_kinds():
    """Every extension point's piece of the schema is its registered kinds' fragments, each kind's class
    (or format) named by its own ``kind``; the solver enum is the registered solvers."""
    from ffdcli.constraints import CONSTRAINTS
    from ffdcli.io.formats import MESH_FORMATS
    from ffdcli.optimize.solvers import SOLVERS
    from ffdcli.parameterization.changes import CHANGES

    schema = design_schema()["properties"]
    assert set(schema["changes"]["items"]["properties"]) == set(CHANGES.kinds()) >= {"twist", "shape", "flap"}
    assert set(schema["constraints"]["items"]["properties"]) == set(CONSTRAINTS.kinds()) >= {"volume", "le_te"}
    assert schema["optimize"]["properties"]["solver"]["enum"] == list(SOLVERS.kinds()) == ["analytic", "su2"]
    assert {"adjoint", "adjoint_residual"} <= set(schema["optimize"]["properties"])    # SU2's own keys
    for registry in (CHANGES, CONSTRAINTS, SOLVERS, MESH_FORMATS):
        assert all(registry[k].kind == k for k in registry.kinds())
        assert all(callable(registry[k].from_spec) for k in registry.kinds())
    assert all(ext in schema["mesh"]["description"] for ext in (".su2", ".cgns", ".vtu", ".vtk"))


def test_a_registry_refuses_a_second_kind_of_a_name_and_a_kind_without_its_parts():
    from ffdcli.registry import Registry

    class A:
        kind = "a"

        @classmethod
        def schema(cls):
            return {}

        @classmethod
        def from_spec(cls, spec, ctx):
            return cls()

    class B(A):
        pass

    class NoSchema:
        kind = "c"
        from_spec = A.from_spec

    reg = Registry("widget")
    assert reg.register(A) is A and reg.register(A) is A and reg.kinds() == ("a",)
    with pytest.raises(ValueError, match="second widget kind named 'a'"):
        reg.register(B)
    with pytest.raises(ValueError, match="has no schema"):
        reg.register(NoSchema)
    with pytest.raises(ValueError, match="non-empty str"):
        reg.register(type("Nameless", (A,), {"kind": ""}))
    assert reg.unknown("z") == "unknown widget 'z'; the kinds are a"


def test_settings_module_is_light():
    """ffdcli.settings imports neither numpy nor the heavy libraries."""
    import subprocess
    import sys

    code = ("import sys, ffdcli.settings; "
            "print(','.join(m for m in ('numpy', 'numba', 'scipy', 'h5py', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == ""
