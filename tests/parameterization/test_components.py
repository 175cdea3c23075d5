"""Several components in one mesh (issue 16): wing + tail + fin, and a wing whose root meets a body.

The oracles are those of SPEC for each component on its own lattice: a dihedral or sweep is a shear
of the whole component (affine, so every surface point of it moves by the same map, 1e-12), a twist
list rotates the tip plane about its trailing-edge point (a lattice end, 1e-12). The surface meshes
are generated here with variety (span along y or z, right and left), the volume meshes are the
bundled gmsh samples.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import run_ffd

from ffdcli.api import DesignModel
from ffdcli.app.deformation import deform
from ffdcli.app.run import load_run
from ffdcli.app.write import write_outputs
from ffdcli.design import load_design
from ffdcli.errors import InputError
from ffdcli.io.formats import read_mesh, write_mesh
from ffdcli.mesh import CellBlock, Mesh
from ffdcli.testing.wings import Planform, surface_mesh

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
EXACT = 1e-12

# (wing/tail sections, fin sections, span sign, fin offset): span along y (fin along z), or span
# along z (fin along y), right or left.
CONFIGS = {
    "span-y": ("xz", "xy", 1.0, (3.1, 0.6, 0.3)),
    "span-y-left": ("xz", "xy", -1.0, (3.1, -0.6, 0.3)),
    "span-z": ("xy", "xz", 1.0, (3.1, 0.3, 0.6)),
}


def planforms(config: str) -> dict[str, Planform]:
    sec, fin_sec, sign, fin_at = CONFIGS[config]
    return {
        "wing": Planform(semi_span=2.5, root_chord=1.0, taper=0.4, le_sweep_deg=25.0, dihedral_deg=2.0,
                         sections=sec, span_sign=sign),
        "htail": Planform(semi_span=1.0, root_chord=0.5, taper=0.6, le_sweep_deg=30.0, root_airfoil="0010",
                          sections=sec, span_sign=sign, root_offset=(3.0, 0.0, 0.0)),
        "vfin": Planform(semi_span=0.7, root_chord=0.5, taper=0.6, le_sweep_deg=35.0, root_airfoil="0010",
                         sections=fin_sec, root_offset=fin_at),
    }


def merged_surface(parts: dict[str, Mesh]) -> Mesh:
    """One surface-only mesh of several, each part's markers merged into one named after the part."""
    pts, markers, at = [], {}, 0
    for name, m in parts.items():
        pts.append(m.points)
        markers[name] = [CellBlock(b.type, b.data + at) for blocks in m.markers.values() for b in blocks]
        at += len(m.points)
    return Mesh(points=np.concatenate(pts), dim=3, cells=[], markers=markers)


def write_parts(tmp: Path, config: str) -> Path:
    pf = planforms(config)
    parts = {n: surface_mesh(p, n_chord=25, n_span=11, root="closed" if n == "vfin" else "open")
             for n, p in pf.items()}
    path = tmp / f"parts_{config}.su2"
    write_mesh(merged_surface(parts), path)
    return path


def write_components(tmp: Path, mesh: Path, comps: list[dict], name: str = "design.yaml", **extra) -> Path:
    data = {"mesh": str(mesh), "components": comps,
            "output": {"mesh": str(tmp / f"out_{Path(name).stem}{mesh.suffix}"),
                       "lattice": str(tmp / f"out_{Path(name).stem}_lattice.vtk")}, **extra}
    path = tmp / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


THREE = [
    {"name": "wing", "surface": "wing", "box": {"points": [5, 6, 2]}, "changes": [{"twist": [0, 1, 2, 3, 4, 6]}]},
    {"name": "htail", "surface": "htail", "box": {"points": [4, 4, 2]}, "changes": [{"dihedral": 5}]},
    {"name": "vfin", "surface": "vfin", "box": {"points": [4, 4, 2]}, "changes": [{"sweep": 10}]},
]


def rotate_about(X, p, c, t, theta_deg):
    th = np.radians(theta_deg)
    Y = X.copy()
    dc, dt = X[:, c] - p[c], X[:, t] - p[t]
    Y[:, c] = p[c] + np.cos(th) * dc + np.sin(th) * dt
    Y[:, t] = p[t] - np.sin(th) * dc + np.cos(th) * dt
    return Y


def by_name(run):
    return {c.name: c for c in run.components}


@pytest.mark.parametrize("config", list(CONFIGS))
def test_each_component_follows_its_own_lattice_exactly(tmp_path, config):
    mesh = write_parts(tmp_path, config)
    run = load_run(load_design(write_components(tmp_path, mesh, THREE)), use_cache=False)
    res = deform(run)
    pf = planforms(config)
    comps = by_name(run)
    # every component has its own axes: the fin spans along the wing's thickness axis
    wing_ax, fin_ax = comps["wing"].box.axes, comps["vfin"].box.axes
    assert fin_ax.span == wing_ax.thickness and fin_ax.chord == wing_ax.chord
    assert comps["htail"].box.axes.span == wing_ax.span
    for name, comp in comps.items():
        ax = comp.box.axes
        c, t, s = ax.chord, ax.thickness, ax.span
        X0 = comp.prep.surface.points
        X1 = res.points[comp.prep.surface.ids]
        d = np.abs(X0[:, s] - pf[name].root_offset[s])             # span distance from the root plane
        if name == "htail":          # dihedral 5 from 0: a shear along the thickness axis, tip up
            np.testing.assert_allclose(X1[:, [c, s]], X0[:, [c, s]], atol=EXACT)
            np.testing.assert_allclose(X1[:, t] - X0[:, t], np.tan(np.radians(5.0)) * d, atol=1e-11)
        elif name == "vfin":         # sweep 35 -> 45 measured along the fin's own span
            np.testing.assert_allclose(X1[:, [t, s]], X0[:, [t, s]], atol=EXACT)
            k = np.tan(np.radians(45.0)) - np.tan(np.radians(35.0))
            np.testing.assert_allclose(X1[:, c] - X0[:, c], k * d, atol=1e-11)
        else:                        # twist list: root fixed, tip rotated 6 degrees about its TE point
            root, tip = d == d.min(), d == d.max()
            np.testing.assert_array_equal(X1[root], X0[root])
            np.testing.assert_allclose(X1[tip], rotate_about(X0[tip], comp.box.te_points[-1], c, t, 6.0),
                                       atol=EXACT)
    # the lattices: one file per component, named after it
    written = write_outputs(run, res)
    assert [Path(written[f"lattice.{n}"]).name for n in comps] == [f"out_design_lattice_{n}.vtk" for n in comps]
    assert "lattice" not in written


def test_variable_names_carry_the_component_and_set_addresses_one(tmp_path):
    mesh = write_parts(tmp_path, "span-y")
    path = write_components(tmp_path, mesh, THREE)
    model = DesignModel.from_file(path, overrides=["components.1.changes.0.dihedral=4"], use_cache=False)
    assert model.names == [f"wing.c0.twist[{j}]" for j in range(6)] + ["htail.c0.dihedral", "vfin.c0.sweep"]
    assert model.values[6] == 4.0
    by_word = DesignModel.from_file(path, overrides=["components.htail.changes.0.dihedral=3"], use_cache=False)
    assert by_word.values[6] == 3.0
    r = run_ffd("vars", str(path), "--json")
    if r.returncode == 0 and r.stdout.strip().startswith("{"):
        names = [v["name"] for v in json.loads(r.stdout)["variables"]]
        assert "htail.c0.dihedral" in names


def test_single_component_file_is_one_component_with_the_old_names(tmp_path):
    mesh = write_parts(tmp_path, "span-y")
    data = {"mesh": str(mesh), "surface": "htail", "box": {"points": [4, 4, 2]}, "changes": [{"dihedral": 5}],
            "output": {"mesh": str(tmp_path / "o.su2")}}
    (tmp_path / "one.yaml").write_text(yaml.safe_dump(data))
    model = DesignModel.from_file(tmp_path / "one.yaml", use_cache=False)
    assert model.names == ["c0.dihedral"] and len(model.run.components) == 1


@pytest.mark.parametrize("config", ["span-y", "span-z"])
def test_surface_derivatives_of_every_component_match_central_differences(tmp_path, config):
    mesh = write_parts(tmp_path, config)
    comps = [dict(c) for c in THREE]
    comps[0] = {**comps[0], "changes": [{"twist": {"tip": 3}}, {"chord": {"tip": 0.8}}]}
    comps[1] = {**comps[1], "changes": [{"dihedral": 5}, {"shape": {"upper": [0, 0.01, 0.01, 0]}}]}
    model = DesignModel.from_file(write_components(tmp_path, mesh, comps), use_cache=False)
    v0 = model.values.copy()
    rng = np.random.default_rng(3)
    g = rng.normal(size=(len(model.surface_ids), 3))
    exact = model.surface_vjp(g)
    for i, name in enumerate(model.names):
        h = 1e-3 if "shape" in name else 1e-2
        vp, vm = v0.copy(), v0.copy()
        vp[i] += h
        vm[i] -= h
        model.set_values(vp)
        jp = np.sum(g * model.surface_points())
        model.set_values(vm)
        jm = np.sum(g * model.surface_points())
        fd = (jp - jm) / (2 * h)
        assert exact[i] == pytest.approx(fd, rel=1e-5, abs=1e-7), name
    model.set_values(v0)
    # the forward product agrees with the transpose (one block per component)
    dv = rng.normal(size=model.n_vars)
    assert np.sum(model.surface_jvp(dv).reshape(-1, 3) * g) == pytest.approx(exact @ dv, rel=1e-10)


# ---------------------------------------------------------------------------------------------
# The volume meshes (bundled gmsh samples)


def sample_design(tmp: Path, sample: str, comps: list[dict], name="design.yaml") -> Path:
    return write_components(tmp, SAMPLES / sample, comps, name=name)


@pytest.mark.slow
def test_wing_tail_fin_volume_one_motion_one_gate(tmp_path):
    path = sample_design(tmp_path, "wing_tail_fin.su2", THREE)
    run = load_run(load_design(path), use_cache=False)
    res = deform(run)
    assert res.quality.n_inverted == 0 and res.quality.ok
    mesh = run.prep.mesh
    far = np.unique(np.concatenate([b.data.ravel() for b in mesh.markers["farfield"]]))
    np.testing.assert_array_equal(res.points[far], mesh.points[far])
    sym = np.unique(np.concatenate([b.data.ravel() for b in mesh.markers["symmetry"]]))
    np.testing.assert_array_equal(res.points[sym, 1], mesh.points[sym, 1])       # slides in y = 0
    for comp in run.components:         # each surface exactly where its own lattice puts it
        ids = comp.prep.surface.ids
        from ffdcli.volume.surface_motion import component_displacement

        P = run.lattices_after()[run.components.index(comp)]
        np.testing.assert_array_equal(res.points[ids], mesh.points[ids] + component_displacement(comp, P))
    moved = np.linalg.norm(res.points - mesh.points, axis=1)
    assert moved.max() > 0.05


@pytest.mark.slow
def test_wing_tail_fin_volume_derivatives_match_central_differences(tmp_path):
    comps = [{"name": "wing", "surface": "wing", "box": {"points": [5, 6, 2]}, "changes": [{"twist": {"tip": 2}}]},
             {"name": "htail", "surface": "htail", "box": {"points": [4, 4, 2]}, "changes": [{"dihedral": 3}]},
             {"name": "vfin", "surface": "vfin", "box": {"points": [4, 4, 2]}, "changes": [{"sweep": 5}]}]
    model = DesignModel.from_file(sample_design(tmp_path, "wing_tail_fin.su2", comps), use_cache=False)
    mesh = model.run.prep.mesh
    rng = np.random.default_rng(0)
    g = rng.normal(size=(mesh.n_points, 3))
    exact = model.mesh_vjp(g)
    v0 = model.values.copy()
    for i, name in enumerate(model.names):
        h = 1e-2
        vals = []
        for sgn in (1, -1):
            v = v0.copy()
            v[i] += sgn * h
            model.set_values(v)
            vals.append(np.sum(g * model.mesh_points()))
        fd = (vals[0] - vals[1]) / (2 * h)
        assert exact[i] == pytest.approx(fd, rel=2e-4, abs=1e-6), name
    model.set_values(v0)


WING_ON_BODY = [{"name": "wing", "surface": "wing", "box": {"points": [5, 8, 2]},
                 "changes": [{"twist": {"tip": 4}}, {"dihedral": 3}]}]


@pytest.mark.slow
def test_wing_on_a_body_keeps_the_body_and_junction_fixed(tmp_path):
    path = sample_design(tmp_path, "wing_body.su2", WING_ON_BODY)
    run = load_run(load_design(path), use_cache=False)
    comp = run.components[0]
    assert comp.junction is not None and comp.junction.marker == "fuselage"
    f = comp.junction.frozen
    assert 2 <= f < comp.box.shape[1]
    res = deform(run)
    assert res.quality.n_inverted == 0
    mesh = run.prep.mesh
    body = np.unique(np.concatenate([b.data.ravel() for b in mesh.markers["fuselage"]]))
    np.testing.assert_allclose(res.points[body], mesh.points[body], atol=1e-12, rtol=0)
    np.testing.assert_array_equal(res.points[comp.junction.nodes], mesh.points[comp.junction.nodes])
    P = run.lattices_after()[0]
    np.testing.assert_array_equal(P[:, :f], comp.P0[:, :f])          # the junction sections, bit for bit
    # the tip still follows the SPEC twist: the {tip} law is re-based on the first free section
    ax = comp.box.axes
    X0 = comp.prep.surface.points
    X1 = res.points[comp.prep.surface.ids]
    assert comp.changes[0].law.values[-1] == 4.0 and np.all(comp.changes[0].law.values[:f] == 0)
    twist_only = load_run(load_design(path, overrides=["components.0.changes.1.dihedral=0"]), use_cache=False)
    tip = X0[:, ax.span] == X0[:, ax.span].max()
    Xt = deform(twist_only).points[comp.prep.surface.ids]
    np.testing.assert_allclose(Xt[tip], rotate_about(X0[tip], comp.box.te_points[-1], ax.chord, ax.thickness, 4.0),
                               atol=EXACT)
    # the wing moves smoothly away from the junction: displacement grows from 0 with the span
    d = np.linalg.norm(X1 - X0, axis=1)
    y = X0[:, ax.span]
    near = y < y.min() + 0.05 * np.ptp(y)
    assert d[near].max() < 1e-3 * d.max()


def test_a_change_that_moves_the_root_of_a_wing_on_a_body_is_refused(tmp_path):
    for changes, key in (([{"twist": [1, 0, 0, 0, 0, 0, 0, 0]}], "components[0].changes[0].twist"),
                         ([{"twist": {"root": -2, "tip": 3}}], "components[0].changes[0].twist.root"),
                         ([{"chord": {"root": 1.1, "tip": 0.8}}], "components[0].changes[0].chord.root")):
        comps = [{**WING_ON_BODY[0], "changes": changes}]
        path = sample_design(tmp_path, "wing_body.su2", comps, name="bad.yaml")
        r = run_ffd("deform", str(path))
        assert r.returncode == 2, (r.stdout + r.stderr)
        assert key in (r.stdout + r.stderr) and "fuselage" in (r.stdout + r.stderr)


def test_generated_wing_on_a_curved_body_root_ring_shared(tmp_path):
    """A wing whose root ring is shared with a curved (non-planar) body marker: C1 at v = 0."""
    pf = Planform(semi_span=2.0, root_chord=1.0, taper=0.5, le_sweep_deg=20, sections="xz")
    wing = surface_mesh(pf, n_chord=25, n_span=9, root="open")
    pts = wing.points
    ring = np.flatnonzero(pts[:, 1] == 0.0)
    # a collar around the root: the ring pushed out in x-z and bent back in y (a body's surface)
    c = pts[ring].mean(axis=0)
    out = pts[ring].copy()
    out[:, [0, 2]] = c[[0, 2]] + 1.6 * (out[:, [0, 2]] - c[[0, 2]])
    out[:, 1] = -0.05 - 0.1 * np.linalg.norm(out[:, [0, 2]] - c[[0, 2]], axis=1)
    order = ring[np.argsort(np.arctan2(pts[ring, 2] - c[2], pts[ring, 0] - c[0]))]
    new = len(pts) + np.arange(len(ring))
    idx = {int(r): int(n) for r, n in zip(ring, new, strict=True)}
    quads = np.array([[a, b, idx[int(b)], idx[int(a)]] for a, b in zip(order, np.roll(order, -1), strict=True)])
    allp = np.concatenate([pts, out])                      # new point len(pts) + k is ring[k] pushed out
    mesh = Mesh(points=allp, dim=3, cells=[], markers={"wing": wing.markers["wing"],
                                                        "body": [CellBlock("quad", quads)]})
    path = tmp_path / "collar.su2"
    write_mesh(mesh, path)
    design = write_components(tmp_path, path, [{"name": "wing", "surface": "wing", "box": {"points": [5, 6, 2]},
                                                "changes": [{"twist": {"tip": 5}}, {"sweep": 5}]}])
    run = load_run(load_design(design), use_cache=False)
    comp = run.components[0]
    assert comp.junction is not None and comp.junction.marker == "body" and comp.junction.frozen == 2
    res = deform(run)
    body = np.unique(quads)
    np.testing.assert_array_equal(res.points[body], read_mesh(path).points[body])
    r = run_ffd("box", str(design), "--json")
    assert r.returncode == 0, (r.stdout + r.stderr)
    assert json.loads(r.stdout)["components"][0]["root_on"] == "body"


def test_inspect_and_box_name_the_body(tmp_path):
    r = run_ffd("inspect", str(SAMPLES / "wing_body.su2"), "--surface", "wing", "--json")
    assert r.returncode == 0, (r.stdout + r.stderr)
    assert json.loads(r.stdout)["root_on"] == "fuselage"
    r = run_ffd("inspect", str(SAMPLES / "wing_tail_fin.su2"), "--surface", "htail", "--json")
    assert json.loads(r.stdout)["root_on"] is None          # the tail's root is on the symmetry plane
    r = run_ffd("box", str(SAMPLES / "wing_body.su2"), "--surface", "wing", "--lattice",
                str(tmp_path / "l.vtk"), "--cache-dir", str(tmp_path), "--json")
    assert r.returncode == 0, (r.stdout + r.stderr)
    s = json.loads(r.stdout)
    assert s["root_on"] == "fuselage" and s["junction"]["frozen_sections"] >= 2


# ---------------------------------------------------------------------------------------------
# Bad input


def expect_error(path, *args, words=()):
    r = run_ffd("deform", str(path), *args)
    assert r.returncode == 2, (r.stdout + r.stderr)
    assert "Traceback" not in (r.stdout + r.stderr)
    for w in words:
        assert w in (r.stdout + r.stderr), (w, (r.stdout + r.stderr))
    return (r.stdout + r.stderr)


def test_bad_components(tmp_path):
    mesh = write_parts(tmp_path, "span-y")
    no_surface = [{"name": "wing", "box": {"points": [5, 6, 2]}}]
    expect_error(write_components(tmp_path, mesh, no_surface, name="a.yaml"), words=("components[0]", "surface"))
    unknown = [{"name": "wing", "surface": "wing"}, {"name": "tail", "surface": "tail"}]
    expect_error(write_components(tmp_path, mesh, unknown, name="b.yaml"), words=("tail", "htail"))
    twice = [{"name": "wing", "surface": "wing"}, {"name": "other", "surface": ["htail", "wing"]}]
    expect_error(write_components(tmp_path, mesh, twice, name="c.yaml"), words=("'wing'", "two components"))
    same = [{"name": "wing", "surface": "wing"}, {"name": "wing", "surface": "htail"}]
    expect_error(write_components(tmp_path, mesh, same, name="d.yaml"), words=("components[1].name",))
    mixed = write_components(tmp_path, mesh, THREE, name="e.yaml", surface="wing")
    expect_error(mixed, words=("surface", "inside each component"))
    ok = write_components(tmp_path, mesh, THREE, name="f.yaml")
    expect_error(ok, "--set", "components.tail.changes.0.dihedral=1", words=("no component named 'tail'", "htail"))
    expect_error(ok, "--set", "components.7.changes.0.dihedral=1", words=("components",))
    badlist = [{**THREE[0], "changes": [{"twist": [0, 1]}]}]
    expect_error(write_components(tmp_path, mesh, badlist, name="g.yaml"),
                 words=("components[0].changes[0].twist", "6 sections"))


def test_overlapping_boxes_are_an_error_naming_both(tmp_path):
    tail = Planform(semi_span=1.0, root_chord=0.5, root_airfoil="0010", sections="xz", root_offset=(3.0, 0, 0))
    # a second surface right inside the tail's box (just above its upper surface)
    pod = Planform(semi_span=0.3, root_chord=0.2, root_airfoil="0010", sections="xz", root_offset=(3.1, 0.4, 0.0))
    parts = {"htail": surface_mesh(tail, n_chord=25, n_span=9), "pod": surface_mesh(pod, n_chord=25, n_span=5)}
    path = tmp_path / "overlap.su2"
    write_mesh(merged_surface(parts), path)
    comps = [{"name": "htail", "surface": "htail", "box": {"points": [4, 4, 2]}},
             {"name": "pod", "surface": "pod", "box": {"points": [4, 3, 2]}}]
    with pytest.raises(InputError, match="overlap") as e:
        load_run(load_design(write_components(tmp_path, path, comps)), use_cache=False)
    assert "htail" in str(e.value) and "pod" in str(e.value)


DPW4 = Path("/work/shared/data/reference-ffd/DPW4_Aircraft__FFD__wingTailFFD.xyz")


def planform_inside(blk: np.ndarray) -> Planform:
    """A tapered, swept wing (chord x, span y, thickness z) well inside a Plot3D block whose edges
    i = 0 / i = -1 are its leading and trailing edges: sections in y planes from 15 % to 85 % of the
    block's y range, chord 70 % of the block's, thickness half the block's height."""
    y = blk[..., 1]
    y0, y1 = y.min() + 0.15 * np.ptp(y), y.min() + 0.85 * np.ptp(y)

    def at(edge, Y):            # x, z of a block edge (i = 0 or -1, mean over k) at y = Y
        e = blk[edge].mean(axis=1)
        return np.interp(Y, e[:, 1], e[:, 0]), np.interp(Y, e[:, 1], e[:, 2])

    (le0, z0), (te0, _) = at(0, y0), at(-1, y0)
    (le1, z1), (te1, _) = at(0, y1), at(-1, y1)
    c0, c1 = 0.7 * (te0 - le0), 0.7 * (te1 - le1)
    h = float(np.min(blk[:, :, -1, 2] - blk[:, :, 0, 2]))
    tc = int(np.clip(50 * h / c0, 4, 12))
    return Planform(semi_span=y1 - y0, root_chord=c0, taper=c1 / c0, root_airfoil=f"00{tc:02d}", sections="xz",
                    le_sweep_deg=float(np.degrees(np.arctan2((le1 + 0.15 * (te1 - le1)) - (le0 + 0.15 * (te0 - le0)),
                                                             y1 - y0))),
                    dihedral_deg=float(np.degrees(np.arctan2(z1 - z0, y1 - y0))),
                    root_offset=(le0 + 0.15 * (te0 - le0), y0, z0))


@pytest.mark.data
@pytest.mark.skipif(not DPW4.exists(), reason="needs ../shared/data/reference-ffd")
def test_dpw4_wing_and_tail_lattice_imports_as_two_components(tmp_path):
    """The DAFoam DPW4 wing + tail FFD file (two Plot3D blocks): one component per block."""
    from ffdcli.io.formats.plot3d import read_plot3d, write_plot3d

    blocks = read_plot3d(DPW4)
    assert len(blocks) == 2
    parts = {name: surface_mesh(planform_inside(blk), n_chord=21, n_span=9)
             for name, blk in zip(("wing", "htail"), blocks, strict=True)}
    path = tmp_path / "dpw4_parts.su2"
    write_mesh(merged_surface(parts), path)
    comps = [{"name": n, "surface": n, "box": {"file": str(DPW4), "block": b, "sections": "xz"},
              "changes": [{"twist": {"tip": 2}}]} for b, n in enumerate(("wing", "htail"))]
    run = load_run(load_design(write_components(tmp_path, path, comps)), use_cache=False)
    for comp, blk in zip(run.components, blocks, strict=True):
        emb = comp.prep.embedding
        assert emb.inside.all() and float(emb.residual.max()) < 1e-9
        assert comp.box.imported and sorted(comp.P0.shape[:3]) == sorted(blk.shape[:3])
    res = deform(run)
    assert res.max_displacement > 0
    # exported again: one block per component, same points as the file (up to the index order)
    out = tmp_path / "again.xyz"
    write_plot3d(out, [c.P0 for c in run.components])
    again = read_plot3d(out)
    for a, b in zip(again, blocks, strict=True):
        np.testing.assert_allclose(np.sort(a.reshape(-1, 3), axis=0), np.sort(b.reshape(-1, 3), axis=0), atol=1e-12)
    # one block chosen out of range, or none for a multi-block file: exit 2 naming box.block
    bad = [{**comps[0], "box": {"file": str(DPW4), "block": 5}}]
    r = run_ffd("deform", str(write_components(tmp_path, path, bad, name="bad.yaml")))
    assert r.returncode == 2 and "block" in r.stderr


def test_constraints_per_component_are_named_after_it_with_exact_jacobians(tmp_path):
    mesh = write_parts(tmp_path, "span-y")
    comps = [{**THREE[0], "changes": [{"twist": {"tip": 3}}, {"chord": {"tip": 0.8}}]},
             {**THREE[1], "changes": [{"dihedral": 5}, {"shape": {"upper": [0, 0.01, 0.01, 0]}}]}, THREE[2]]
    model = DesignModel.from_file(write_components(tmp_path, mesh, comps), use_cache=False)
    model.set_constraints([{"volume": {"lower": 1.0}}], component=0)
    model.set_constraints([{"thickness": {"chord": [0.3, 0.6], "span": [0.3, 0.7], "lower": 1.0}}], component=1)
    assert model.constraint_names == ["wing.k0.volume"] + [f"htail.k0.thickness[{j}]" for j in range(4)]
    J = model.constraint_jacobian()
    v0 = model.values.copy()
    for i in range(model.n_vars):
        h = 1e-3 if "shape" in model.names[i] else 1e-2
        vals = []
        for sgn in (1, -1):
            v = v0.copy()
            v[i] += sgn * h
            model.set_values(v)
            vals.append(model.constraint_values())
        np.testing.assert_allclose(J[:, i], (vals[0] - vals[1]) / (2 * h), rtol=1e-5, atol=1e-8,
                                   err_msg=model.names[i])
    model.set_values(v0)
    # a wing constraint does not see the tail's variables, and the other way round
    tail = [i for i, n in enumerate(model.names) if n.startswith("htail.")]
    assert np.all(J[0, tail] == 0)
    assert np.any(J[1:, tail] != 0)
