"""Issue 43, item 1: for every design variable, the column of ``ffd jacobian`` is the derivative of
what ``ffd deform`` writes for that value, and ``ffd deform`` of a design with new values writes what
the model set to those values computes (one code path evaluates a design, whoever asks).

The reference is the deform workflow itself, the design file rewritten with the value moved each
way (``load_design`` -> ``load_run`` -> ``deform``): a variable hinge's knots, rows and hinge point
are rebuilt from the file each time, as ``ffd deform`` does. Designs are drawn from seeds: several
planforms, device spans and hinge values (flap and slat, straight and tapered hinge lines, the
devices before and after other changes), so no one replayed case stands for the rule.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
import scipy.sparse as sp
import yaml
from wingcase import write_design, write_surface_wing

from ffdcli.api.gradient import jacobian_design
from ffdcli.app.deformation import deform
from ffdcli.app.run import load_run
from ffdcli.design import load_design
from ffdcli.optimize.best import best_design_data, value_path

STEP = 1e-6
#: a column against the central differences of deform, relative to the column's largest entry
REL = 1e-5


def _place(data: dict, name: str, value: float) -> dict:
    out = copy.deepcopy(data)
    path = value_path(name, out)
    cur = out
    for key in path[:-1]:
        cur = cur[key]
    cur[path[-1]] = float(value)
    return out


def _deformed_surface(path, data: dict, tmp_path):
    """The surface ``ffd deform`` writes for design ``data`` (the file at ``path`` rewritten)."""
    f = tmp_path / "moved.yaml"
    f.write_text(yaml.safe_dump(data, sort_keys=False))
    run = load_run(load_design(f))
    res = deform(run, check=False, recover=False)
    return res.points[run.surface_ids]


def _designs(seed: int) -> tuple[dict, list]:
    """(planform, changes) of a drawn design: each variable kind, a variable-hinge flap or slat."""
    rng = np.random.default_rng(seed)
    planform = dict(le_sweep_deg=float(rng.uniform(0, 30)), taper=float(rng.uniform(0.4, 1.0)))
    a = float(rng.uniform(0.1, 0.35))
    span = [round(a, 3), round(a + float(rng.uniform(0.3, 0.5)), 3)]
    if seed % 2:
        h = rng.uniform(0.13, 0.28, size=2)
        device = {"slat": {"span": span, "hinge": [round(float(x), 3) for x in h],
                           "angle": round(float(rng.uniform(-15, 15)), 2)}}
    else:
        h = rng.uniform(0.62, 0.78, size=2)
        device = {"flap": {"span": span, "hinge": [round(float(x), 3) for x in h],
                           "angle": round(float(rng.uniform(-20, 20)), 2)}}
    if seed % 3 == 0:        # a tapered line and a range of its own
        key = next(iter(device))
        lo, hi = (0.55, 0.85) if key == "flap" else (0.1, 0.32)
        device[key]["hinge_range"] = [lo, hi]
        device[key]["hinge"][1] = round(float(rng.uniform(lo + 0.01, hi - 0.01)), 3)
    before = [{"twist": {"root": round(float(rng.uniform(-2, 2)), 2), "tip": round(float(rng.uniform(-4, 4)), 2)}},
              {"chord": {"tip": round(float(rng.uniform(0.8, 1.1)), 3)}}]
    after = [{"sweep": round(float(rng.uniform(-5, 5)), 2)}, {"dihedral": round(float(rng.uniform(-3, 3)), 2)},
             {"span": round(float(rng.uniform(0.95, 1.08)), 3)}]
    changes = before + [device] + after if seed % 2 == 0 else [device] + before + after
    return planform, changes


def _check_columns(tmp_path, planform: dict, changes: list, only=None) -> list[str]:
    mesh = write_surface_wing(tmp_path, **planform)
    path = write_design(tmp_path, mesh, changes, volume={"method": "none"})
    design = load_design(path)
    data = yaml.safe_load(path.read_text())
    jacobian_design(design, tmp_path / "jac.npz")
    jac = np.load(tmp_path / "jac.npz")
    names, values, D = list(jac["names"]), jac["values"], jac["D"]
    B = sp.csr_matrix((jac["B_data"], jac["B_indices"], jac["B_indptr"]), shape=tuple(jac["B_shape"]))
    bad = []
    for q, name in enumerate(names):
        if only is not None and not any(word in name for word in only):
            continue
        up = _deformed_surface(path, _place(data, name, values[q] + STEP), tmp_path)
        down = _deformed_surface(path, _place(data, name, values[q] - STEP), tmp_path)
        fd = (up - down) / (2 * STEP)
        col = np.asarray(B @ D[:, q].reshape(-1, 3))
        err, scale = np.abs(col - fd).max(), np.abs(fd).max()
        if err > REL * max(scale, 1e-3):
            bad.append((name, float(err), float(scale)))
    assert not bad, bad
    return names


@pytest.mark.slow
@pytest.mark.parametrize("seed", [2, 3])
def test_every_column_is_the_derivative_of_what_deform_writes(tmp_path, seed):
    planform, changes = _designs(seed)
    names = _check_columns(tmp_path, planform, changes)
    kinds = {n.split(".")[1].split("[")[0] for n in names}
    assert {"twist", "chord", "sweep", "dihedral", "span"} <= kinds
    assert any("hinge[0]" in n for n in names) and any("hinge[1]" in n for n in names)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 4, 5, 7])
def test_device_columns_are_the_derivatives_of_what_deform_writes(tmp_path, seed):
    """More drawn devices (flap and slat, straight and tapered lines, default and given ranges),
    their angle and hinge columns."""
    planform, changes = _designs(seed)
    _check_columns(tmp_path, planform, changes, only=("hinge", "angle"))


def test_shape_columns(tmp_path):
    rng = np.random.default_rng(11)
    shape = {"shape": {"upper": [round(float(x), 4) for x in rng.uniform(-0.01, 0.01, 6)],
                       "lower": [round(float(x), 4) for x in rng.uniform(-0.01, 0.01, 6)]}}
    _check_columns(tmp_path, {"le_sweep_deg": 15.0, "taper": 0.6}, [{"twist": {"tip": 2}}, shape])


def test_the_issues_slat_hinge(tmp_path):
    """The probe's case on a wing of the tests: slat {span: [0.2, 0.8], hinge: [0.15, 0.2], angle: 10};
    its hinge[0] column was 0.177 where deform moved by 0.401 (the knots stayed at the file's hinge)."""
    _check_columns(tmp_path, {}, [{"slat": {"span": [0.2, 0.8], "hinge": [0.15, 0.2], "angle": 10}}],
                   only=("hinge",))


def test_best_yaml_reproduces_the_model(tmp_path):
    """What ``ffd optimize`` writes as ``best.yaml`` (the values written into the design) deforms to
    the surface the model computed at those values, for drawn values of every variable."""
    planform, changes = _designs(4)
    mesh = write_surface_wing(tmp_path, **planform)
    path = write_design(tmp_path, mesh, changes, volume={"method": "none"})
    design = load_design(path)
    run = load_run(design)
    names, values = run.variables()
    rng = np.random.default_rng(5)
    for _ in range(3):
        v = values.copy()
        for q, name in enumerate(names):
            if "hinge" in name:
                v[q] = values[q] + rng.uniform(-0.04, 0.04)
            elif "angle" in name or "twist" in name:
                v[q] = values[q] + rng.uniform(-3, 3)
        run.set_values(v)
        model = run.prep.surface.points + run.surface_displacement(run.lattices_after())
        data = best_design_data(design, _Settings(tmp_path), names, v, tmp_path / "best.yaml", tmp_path / "best.su2")
        data.pop("optimize", None)
        (tmp_path / "best.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
        best = load_run(load_design(tmp_path / "best.yaml"))
        written = deform(best, check=False, recover=False).points[best.surface_ids]
        chord = 1.0
        assert np.abs(written - model).max() < 1e-12 * chord


class _Settings:
    """The two paths of ``optimize:`` that ``best_design_data`` rebases."""

    def __init__(self, folder):
        self.config = folder / "flow.cfg"
        self.folder = folder
