"""Issue 48: ffd as the geometry of MPhys run scripts (ffdcli.mphys): pyGeo's interface mapped onto ffd's
design variables and constraints, the outputs against DesignModel, exact totals through a stand-in
aerodynamic discipline, the automatic box of a surface point set, and the Builder's wiring."""

from __future__ import annotations

import importlib.util
import sys
import warnings

import numpy as np
import pytest
import yaml
from conftest import REPO
from wingcase import write_design, write_surface_wing

pytest.importorskip("mphys", reason="mphys is not installed (pip install 'ffdcli[mphys]')")
om = pytest.importorskip("openmdao.api", reason="openmdao is not installed (pip install 'ffdcli[mphys]')")

from mphys import MPhysVariables, Multipoint, MultipointParallel  # noqa: E402
from mphys.scenarios import ScenarioAerodynamic  # noqa: E402

from ffdcli.api import DesignModel  # noqa: E402
from ffdcli.errors import InputError  # noqa: E402
from ffdcli.io.formats.plot3d import write_plot3d  # noqa: E402
from ffdcli.mphys import FFDBuilder, FFDGeometry, FFDNote  # noqa: E402
from ffdcli.openmdao import add_design_vars  # noqa: E402

GEO = MPhysVariables.Aerodynamics.Surface.Geometry


def _standin():
    spec = importlib.util.spec_from_file_location("mphys_standin_aero", REPO / "examples" / "mphys_standin_aero.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["mphys_standin_aero"] = mod
    spec.loader.exec_module(mod)
    return mod


STANDIN = _standin()


@pytest.fixture
def wing(tmp_path):
    """A swept tapered surface wing (chord x, span y, up z), its design file (no changes) and the solver's
    surface: the wing marker's points (a flow solver's wall nodes are the mesh's), in another order."""
    mesh = write_surface_wing(tmp_path, sections="xz", taper=0.6, le_sweep_deg=15)
    design = write_design(tmp_path, mesh, [], points=(6, 5, 2), sections="xz")
    X = DesignModel.from_file(design).surface_points()
    X = X[np.random.default_rng(3).permutation(len(X))]
    np.savez(tmp_path / "surface.npz", points=X, triangles=np.zeros((0, 3), dtype=int))
    return tmp_path, design, X


class Top(Multipoint):
    """MACH-Aero's wiring (MPhys's mphys_aero_opt.py) with a configure callback for the geometry calls."""

    def initialize(self):
        self.options.declare("geometry")
        self.options.declare("surface")
        self.options.declare("calls")

    def setup(self):
        aero = STANDIN.StandinAeroBuilder(self.options["surface"], length=1.0, x_ref=0.5)
        aero.initialize(self.comm)
        self.add_subsystem("mesh", aero.get_mesh_coordinate_subsystem())
        self.add_subsystem("geometry", self.options["geometry"])
        self.mphys_add_scenario("cruise", ScenarioAerodynamic(aero_builder=aero))
        self.connect(f"mesh.{MPhysVariables.Aerodynamics.Surface.Mesh.COORDINATES}",
                     f"geometry.{GEO.COORDINATES_INPUT}")
        self.connect(f"geometry.{GEO.COORDINATES_OUTPUT}", "cruise.x_aero")

    def configure(self):
        super().configure()
        self.options["calls"](self.geometry, self.mesh.mphys_get_surface_mesh())


def _problem(folder, geometry, calls, mode="rev"):
    prob = om.Problem(Top(geometry=geometry, surface=folder / "surface.npz", calls=calls), reports=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FFDNote)
        prob.setup(mode=mode)
    return prob


def _mach_calls(geo, points):
    """pyGeo's calls of MACH-Aero's script, as written there."""
    geo.nom_add_discipline_coords(GEO, points)
    n_ref = geo.nom_addRefAxis(name="wing", xFraction=0.25, alignIndex="k")
    geo.nom_addGlobalDV(dvName="twist", value=np.zeros(n_ref - 1), func=lambda val, g: None)
    geo.nom_addLocalDV(dvName="thickness", axis="z")
    geo.nom_addGlobalDV("span", value=1.0)
    geo.nom_addThicknessConstraints2D("thickcon", None, None, nSpan=3, nChord=4)
    geo.nom_addVolumeConstraint("volcon", None, None)
    geo.nom_add_LETEConstraint("lecon", 0, "iLow")
    geo.nom_add_LETEConstraint("tecon", 0, "iHigh")


def _set(prob, rng):
    prob.set_val("geometry.twist", rng.uniform(-3, 3, size=len(prob.get_val("geometry.twist"))))
    prob.set_val("geometry.thickness", rng.uniform(-0.01, 0.01, size=len(prob.get_val("geometry.thickness"))))
    prob.set_val("geometry.span", 1.0 + rng.uniform(-0.1, 0.1))


@pytest.mark.parametrize("seed", [0, 1])
def test_mach_aero_calls_give_design_model_outputs_and_exact_totals(wing, seed):
    folder, design, X = wing
    prob = _problem(folder, FFDGeometry(design=str(design), work_dir=str(folder / "w")), _mach_calls)
    geo = prob.model.geometry
    m = geo.model.lattice().shape[1]
    assert len(prob.get_val("geometry.twist")) == m - 1                      # the root held, as MACH-Aero's
    assert geo.input_variables("twist") == [f"c0.twist[{j}]" for j in range(1, m)]
    assert len(prob.get_val("geometry.thickness")) == 2 * 6 * m               # every upper and lower point
    rng = np.random.default_rng(seed)
    _set(prob, rng)
    prob.run_model()
    # the outputs are DesignModel's of the same values
    ref = DesignModel.from_file(geo.model.run.design.path)          # the design file the component wrote
    ref.set_constraints([{"thickness": {"chord": [0.125, 0.375, 0.625, 0.875], "span": [0.0, 0.5, 1.0]}},
                         {"volume": {}}, {"le_te": {}}])               # pyGeo's calls in ffd's words
    values = dict(zip(ref.names, ref.values))
    for name in ("twist", "thickness", "span"):
        values.update(zip(geo.input_variables(name), np.atleast_1d(prob.get_val(f"geometry.{name}"))))
    ref.set_values(values)
    ref.add_points("s", X)
    np.testing.assert_allclose(prob.get_val(f"geometry.{GEO.COORDINATES_OUTPUT}").reshape(-1, 3), ref.points("s"),
                               rtol=0, atol=1e-13)
    cv = dict(zip(ref.constraint_names, ref.constraint_values()))
    np.testing.assert_allclose(prob.get_val("geometry.volcon"), [cv["k1.volume"]], rtol=1e-14)
    np.testing.assert_allclose(prob.get_val("geometry.thickcon"), [cv[f"k0.thickness[{j}]"] for j in range(12)],
                               rtol=1e-14)
    lete = [cv[n] for n in ref.constraint_names if n.startswith("k2.")]
    np.testing.assert_allclose(np.sort(np.r_[prob.get_val("geometry.lecon"), prob.get_val("geometry.tecon")]),
                               np.sort(lete), atol=1e-15)
    assert len(prob.get_val("geometry.lecon")) == len(prob.get_val("geometry.tecon")) == m
    # totals of the whole problem, forward and reverse, against central differences
    for mode in ("fwd", "rev"):
        prob = _problem(folder, FFDGeometry(design=str(design), work_dir=str(folder / "w")), _mach_calls, mode)
        _set(prob, np.random.default_rng(seed))
        prob.run_model()
        data = prob.check_totals(of=["cruise.cd", "cruise.cl", "geometry.thickcon", "geometry.volcon",
                                     "geometry.lecon"],
                                 wrt=["geometry.twist", "geometry.thickness", "geometry.span"], method="fd",
                                 form="central", step=1e-6, out_stream=None)
        for key, d in data.items():
            fd, an = d["J_fd"], d[f"J_{mode}"]
            np.testing.assert_allclose(an, fd, atol=2e-6 * max(np.abs(fd).max(), 1e-3), err_msg=f"{key} {mode}")


def test_pygeo_calls_that_ffd_maps_say_so_or_refuse_with_what_to_give(wing):
    folder, design, X = wing
    seen = {}

    def calls(geo, points):
        geo.nom_add_discipline_coords("aero", points)
        with pytest.warns(FFDNote, match="reference axis"):
            seen["n_ref"] = geo.nom_addRefAxis("wing")
        with pytest.warns(FFDNote, match="callback 'twist' is not called"):
            def twist(val, g):
                pass
            geo.nom_addGlobalDV("twist", np.zeros(seen["n_ref"]), twist)
        with pytest.raises(InputError, match="sections: give"):
            geo.nom_addGlobalDV("chord", np.ones(2))
        with pytest.raises(InputError, match="does not call pyGeo callbacks"):
            geo.nom_addGlobalDV("bend", np.zeros(3), lambda v, g: None)
        with pytest.raises(InputError, match="nom_add_LETEConstraint|shape variable first"):
            geo.nom_add_LETEConstraint("lecon", 0, "iLow")
        with pytest.raises(InputError, match="iLow"):
            geo.nom_add_LETEConstraint("lecon", 0, "kLow")
        with pytest.raises(InputError, match="ratios to the baseline"):
            geo.nom_addVolumeConstraint("v", None, None, scaled=False)
        for name in ("nom_addChild", "nom_addLocalSectionDV", "nom_addSurfaceAreaConstraint",
                     "nom_addThicknessConstraints1D"):
            with pytest.raises(InputError, match="ffd has no equivalent; use"):
                getattr(geo, name)("x")
        with pytest.raises(InputError, match="no design variable named 'c9'"):
            geo.nom_add_variables("x", "c9")
        with pytest.raises(InputError, match="add devices before the per-section"):
            geo.nom_add_change("flap", {"flap": {"span": [0.3, 0.8], "hinge": 0.7, "angle": 0}})
        seen["sweep"] = geo.nom_addGlobalDV("sweep", value=2.0)
        with pytest.raises(InputError, match="already moved by the input 'sweep'"):
            geo.nom_addGlobalDV("same_sweep", variables="c1")

    prob = _problem(folder, FFDGeometry(design=str(design), work_dir=str(folder / "w")), calls)
    geo = prob.model.geometry
    assert seen["n_ref"] == geo.model.lattice().shape[1]
    assert geo.input_variables("twist") == [f"c0.twist[{j}]" for j in range(seen["n_ref"])]
    assert seen["sweep"] == 1 and geo.input_variables("sweep") == ["c1.sweep"]
    np.testing.assert_array_equal(prob.get_val("geometry.sweep"), [2.0])
    assert any("reference axis" in n for n in geo.notes)


def test_global_variables_by_the_kind_of_a_change_of_the_design_file(wing):
    """``nom_addGlobalDV(kind, value)`` on a design that has that change: its variables (the first held when
    one value fewer), devices by name too; a size that fits neither is refused in words."""
    folder, design, X = wing
    data = yaml.safe_load(design.read_text())
    data["changes"] = [{"flap": {"span": [0.3, 0.8], "hinge": 0.7, "angle": 5}}, {"twist": {"root": 0, "tip": 2}}]
    design.write_text(yaml.safe_dump(data))
    seen = {}

    def calls(geo, points):
        geo.nom_add_discipline_coords(GEO, points)
        seen["twist"] = geo.nom_addGlobalDV("twist", np.array([2.0]))
        seen["flap"] = geo.nom_addGlobalDV("flap", func=None)
        with pytest.raises(InputError, match="has 2 variables: give 2, or 1"):
            geo.nom_addGlobalDV("twist", np.zeros(3))

    prob = _problem(folder, FFDGeometry(design=str(design), work_dir=str(folder / "w")), calls)
    geo = prob.model.geometry
    assert geo.input_variables("twist") == ["c1.twist.tip"] and seen["twist"] == 1
    assert geo.input_variables("flap") == [n for n in geo.model.names if n.startswith("c0.flap")]
    prob.set_val("geometry.twist", 3.0)
    prob.run_model()
    ref = DesignModel.from_file(design)
    ref.set_values({"c1.twist.tip": 3.0})
    ref.add_points("s", X)
    np.testing.assert_allclose(prob.get_val(f"geometry.{GEO.COORDINATES_OUTPUT}").reshape(-1, 3), ref.points("s"),
                               rtol=0, atol=1e-13)


def test_pygeo_lattice_file_and_point_set_box(wing):
    """No design file: the automatic box fitted to the solver's surface points equals the mesh's box; a
    pyGeo FFD file (Plot3D) is taken as box.file around the same points."""
    folder, design, X = wing
    changes = {"twist": {"root": 0, "tip": 4}}

    def calls(geo, points):
        geo.nom_add_discipline_coords(GEO, points)
        geo.nom_add_change("t", changes)

    on_mesh = _problem(folder, FFDGeometry(design=str(design), work_dir=str(folder / "a")), calls)
    cloud = _problem(folder, FFDGeometry(box={"points": [6, 5, 2], "sections": "xz"}, work_dir=str(folder / "b")),
                     calls)
    for p in (on_mesh, cloud):
        p.set_val("geometry.t", [0.5, 4.0])
        p.run_model()
    a = on_mesh.get_val(f"geometry.{GEO.COORDINATES_OUTPUT}")
    b = cloud.get_val(f"geometry.{GEO.COORDINATES_OUTPUT}")
    assert np.abs(a - X.ravel()).max() > 1e-3                       # it moved
    np.testing.assert_allclose(cloud.model.geometry.model.lattice(), on_mesh.model.geometry.model.lattice(),
                               rtol=0, atol=1e-12)                    # one wing, one box: faces or not
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)
    lattice = folder / "ffd.xyz"
    write_plot3d(lattice, [DesignModel.from_file(design).lattice()])
    with pytest.warns(FFDNote, match="taken as the lattice of ffd's box"):
        prob = om.Problem(Top(geometry=FFDGeometry(file=str(lattice), type="ffd", work_dir=str(folder / "c")),
                              surface=folder / "surface.npz", calls=calls), reports=False)
        prob.setup()
    prob.set_val("geometry.t", [0.5, 4.0])
    prob.run_model()
    np.testing.assert_allclose(prob.get_val(f"geometry.{GEO.COORDINATES_OUTPUT}"), a, atol=1e-10)


def test_aero_and_struct_coordinates_read_at_first_compute_and_reembedded_when_they_change(wing):
    """Two disciplines (an aerostructural script): the wall points and points inside the wing (a wing box's
    nodes) read from their inputs at the first compute, moved by one box, re-embedded when they change."""
    folder, design, X = wing
    data = yaml.safe_load(design.read_text())
    data["changes"] = [{"twist": {"root": 0, "tip": 3}}, {"chord": {"tip": 0.8}}]
    design.write_text(yaml.safe_dump(data))
    STRUCT = MPhysVariables.Structures.Geometry
    inner = 0.5 * (X + X.mean(axis=0) * np.array([1, 0, 1]) + X * np.array([0, 1, 0]))   # pulled inside
    prob = om.Problem(reports=False)
    ivc = prob.model.add_subsystem("ivc", om.IndepVarComp())
    ivc.add_output("x", val=X.ravel())
    ivc.add_output("s", val=inner.ravel())
    prob.model.add_subsystem("geo", FFDGeometry(design=str(design), disciplines=("aero", STRUCT),
                                                dvs={"tw": "c0.twist", "ch": ["c1.chord"]}, work_dir=str(folder / "w")))
    prob.model.connect("ivc.x", f"geo.{GEO.COORDINATES_INPUT}")
    prob.model.connect("ivc.s", f"geo.{STRUCT.COORDINATES_INPUT}")
    prob.setup()
    geo = prob.model.geo
    prob.run_model()
    ref = DesignModel.from_file(design)
    for name, P in (("x", X), ("s", inner), ("x2", X * 1.001)):
        ref.add_points(name, P)
    np.testing.assert_allclose(prob.get_val(f"geo.{GEO.COORDINATES_OUTPUT}").reshape(-1, 3), ref.points("x"),
                               rtol=0, atol=1e-13)
    np.testing.assert_allclose(prob.get_val(f"geo.{STRUCT.COORDINATES_OUTPUT}").reshape(-1, 3), ref.points("s"),
                               rtol=0, atol=1e-13)
    assert np.abs(ref.points("s") - inner).max() > 1e-3
    prob.set_val("ivc.x", (X * 1.001).ravel())
    prob.run_model()
    np.testing.assert_allclose(prob.get_val(f"geo.{GEO.COORDINATES_OUTPUT}").reshape(-1, 3), ref.points("x2"),
                               rtol=0, atol=1e-13)
    assert geo.input_names == ["tw", "ch"] and geo.input_variables("tw") == ["c0.twist.root", "c0.twist.tip"]
    with pytest.raises(InputError, match="c0.twist.tip is already moved by the input 'tw'"):
        geo.nom_add_variables("again", "c0.twist.tip")
    with pytest.raises(InputError, match="the points of 'p'"):
        geo.nom_addPointSet(np.zeros((4, 2)), "p")
    with pytest.raises(InputError, match="exists already"):
        geo.nom_add_discipline_coords("struct", inner)


def test_design_file_variables_and_constraints_and_the_builder_wires_the_parallel_scenario(wing):
    """FFDBuilder in ScenarioAerodynamic(in_MultipointParallel=True): no hand connection of coordinates;
    the design file's changes are inputs (FFDComponent's names) and its constraints outputs."""
    folder, design, X = wing
    data = yaml.safe_load(design.read_text())
    data["changes"] = [{"flap": {"span": [0.3, 0.8], "hinge": 0.7, "angle": 5}}, {"twist": {"root": 0, "tip": 2}},
                       {"dihedral": 1}]
    data["constraints"] = [{"volume": {"lower": 1.0}}]
    design.write_text(yaml.safe_dump(data))
    geo = FFDBuilder(design=str(design), work_dir=str(folder / "w"))

    class Parallel(MultipointParallel):
        def setup(self):
            aero = STANDIN.StandinAeroBuilder(folder / "surface.npz", length=1.0, x_ref=0.5, initial=True)
            self.mphys_add_scenario("cruise", ScenarioAerodynamic(aero_builder=aero, geometry_builder=geo,
                                                                  in_MultipointParallel=True))

    prob = om.Problem(reports=False)
    prob.model.add_subsystem("mp", Parallel())
    prob.model.add_objective("mp.cruise.cd")
    prob.setup(mode="rev")
    comp = prob.model.mp.cruise.geometry
    assert comp.input_names == ["c0_flap", "c1_twist", "c2_dihedral"]
    names = add_design_vars(prob.model, comp, prefix="mp.cruise.geometry.")
    assert names == ["mp.cruise.geometry.c0_flap", "mp.cruise.geometry.c1_twist", "mp.cruise.geometry.c2_dihedral"]
    prob.setup(mode="rev")
    prob.run_model()
    ref = DesignModel.from_file(design)
    ref.add_points("s", X)
    np.testing.assert_allclose(prob.get_val("mp.cruise.x_aero").reshape(-1, 3), ref.points("s"), atol=1e-13)
    np.testing.assert_allclose(prob.get_val("mp.cruise.geometry.k0_volume"), ref.constraint_values(), rtol=1e-14)
    data = prob.check_totals(of=["mp.cruise.cd", "mp.cruise.geometry.k0_volume"], method="fd", form="central",
                             step=1e-6, out_stream=None)
    for key, d in data.items():
        np.testing.assert_allclose(d["J_rev"], d["J_fd"], atol=2e-6 * max(np.abs(d["J_fd"]).max(), 1e-3),
                                   err_msg=str(key))


@pytest.mark.slow
def test_example_mach_aero_wing_runs_with_exact_totals_and_optimises(tmp_path):
    """examples/mphys_aero_wing.py: prepare, run (check_totals forward and reverse) and opt on a small wing."""
    spec = importlib.util.spec_from_file_location("mphys_aero_wing", REPO / "examples" / "mphys_aero_wing.py")
    ex = importlib.util.module_from_spec(spec)
    sys.modules["mphys_aero_wing"] = ex
    spec.loader.exec_module(ex)
    ex.prepare(tmp_path, 21, 7)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FFDNote)
        out = ex.run(tmp_path, "ffd", check=True)
        opt = ex.optimize(tmp_path, "ffd", iterations=40)
    X0 = np.load(tmp_path / "surface.npz")["points"]
    assert np.abs(np.array(out["x_aero"]) - X0).max() > 1e-2          # twist and shape moved it
    for mode in ("fwd", "rev"):
        for key, d in out[f"check_totals_{mode}"].items():
            assert d["abs"] <= 1e-6 * max(d["fd"], 1e-3), (mode, key, d)
    np.testing.assert_allclose(out["geometry.tecon"], 0.0, atol=1e-15)   # the shape moves edges symmetrically
    assert opt["success"] and opt["cl"] == pytest.approx(0.5, abs=1e-6)
    assert min(opt["thickness"]) >= 1 - 1e-6 and opt["volume"] >= 1 - 1e-6
