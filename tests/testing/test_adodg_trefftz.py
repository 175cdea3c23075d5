"""benchmarks/adodg/trefftz.py against exact answers: the Trefftz plane of the elliptic load (a flat
plate moving normal to itself: e = 1), linear interpolation of a linear field, SU2's restart layout."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.adodg import trefftz as T
from benchmarks.adodg.evaluate import write_restart


def plate_flow(y, z, s, V):
    """(v, w) of a flat plate |y| < s, z = 0, moving in -z at speed V through fluid at rest (the
    Trefftz-plane flow of an elliptic load: the wake's circulation 2 V sqrt(s^2 - y^2))."""
    zeta = y + 1j * np.where(z == 0, 1e-12, z)
    W = 1j * V * (1.0 - zeta / (np.sqrt(zeta - s) * np.sqrt(zeta + s)))
    return W.real, -W.imag


@pytest.fixture(scope="module")
def plate():
    s, V = 3.011, 0.1                        # the edge between nodes: the field is singular there
    y, z = T.plane_grid(h=0.02)
    yy, zz = np.meshgrid(y, z, indexing="ij")
    v, w = plate_flow(yy, zz, s, V)
    return s, V, y, z, v, w


def test_plate_energy_is_the_added_mass_energy(plate):
    s, V, y, z, v, w = plate
    cross, axial = T.crossflow_integral(y, z, np.zeros_like(v), v, w, 0.5)
    assert axial == 0.0
    assert cross == pytest.approx(math.pi * s * s * V * V / 2, rel=5e-3)   # half of rho pi s^2 V^2 / rho


def test_plate_circulation_is_elliptic(plate):
    s, V, y, z, v, w = plate
    gamma = T.circulation(y, z, v, w)
    exact = 2 * V * np.sqrt(np.clip(s * s - y * y, 0, None))
    assert np.max(np.abs(gamma - exact)) < 0.03 * exact[0]
    inner = y < 2.5
    assert np.max(np.abs(gamma[inner] - exact[inner])) < 0.005 * exact[0]


@pytest.mark.parametrize("n, tol", [(200, 4e-3), (400, 2e-3)])
def test_elliptic_sheet_has_e_one(n, tol):
    y = np.concatenate([np.linspace(0, 3.4, n), [4.0, 6.0]])
    gamma = np.sqrt(np.clip(1 - (y / T.SPAN) ** 2, 0, None))
    assert T.sheet_efficiency(y, gamma) == pytest.approx(1.0, abs=tol)


def test_sheet_energy_of_uniform_load_grows_with_refinement():
    """A uniform load has unbounded induced drag (two point vortices): refining raises it without bound."""
    energies = []
    for n in (50, 200, 800):
        y = np.linspace(0, T.SPAN, n)
        energies.append(T.sheet_energy(y, np.ones(n)))
    assert energies[0] < energies[1] < energies[2]


def test_plate_e_from_its_own_plane(plate):
    """The plane's circulation gives the sheet the same lift and energy as the exact load on the same
    stations (the sheet's own error, largest where the load's square-root edge falls between stations,
    is the same for both: 1.8 % for this edge at h = 0.02, 0.3 % with the edge on a station, above)."""
    s, V, y, z, v, w = plate
    gamma = T.circulation(y, z, v, w)
    exact = 2 * V * np.sqrt(np.clip(s * s - y * y, 0, None))
    assert np.trapezoid(gamma, y) == pytest.approx(np.trapezoid(exact, y), rel=1e-3)
    assert T.sheet_energy(y, gamma) == pytest.approx(T.sheet_energy(y, exact), rel=1e-2)
    assert T.sheet_efficiency(y, gamma) == pytest.approx(T.sheet_efficiency(y, exact), rel=5e-3)


def test_solution_plane_reproduces_a_linear_field_in_wind_axes():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-4, 4, size=(4000, 3))
    pts[:8] = [[sx * 4, sy * 4, sz * 4] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]   # hull corners
    alpha, u_inf = 4.0, 0.6
    axes = T.wind_axes(alpha)
    grad = rng.normal(size=(3, 3)) * 1e-3
    vel = u_inf * axes[0] + pts @ grad.T
    sol = T.Solution(pts, vel, alpha, 0.5, u_inf=u_inf)
    y, z = np.linspace(0, 2, 5), np.linspace(-1, 1, 4)
    u, v, w = sol.plane(0.5, np.array([1.0, 0, 0]), y, z)
    yy, zz = np.meshgrid(y, z, indexing="ij")
    xyz = np.array([1.0, 0, 0]) + 0.5 * axes[0] + yy[..., None] * axes[1] + zz[..., None] * axes[2]
    exact = (xyz @ grad.T) @ axes.T
    np.testing.assert_allclose(np.stack([u, v, w], -1), exact, atol=1e-12)


def test_wind_axes_orthonormal_and_lift_up():
    a = T.wind_axes(4.22)
    np.testing.assert_allclose(a @ a.T, np.eye(3), atol=1e-15)
    assert a[2, 2] > 0 and a[0, 2] > 0 and np.linalg.det(a) == pytest.approx(1.0)


def test_read_restart_round_trip_and_refusal(tmp_path):
    names = ["x", "y", "z", "Velocity_x"]
    data = np.arange(12.0).reshape(3, 4)
    write_restart(tmp_path / "r.dat", names, data)
    raw = (tmp_path / "r.dat").read_bytes()
    out = T.read_restart(tmp_path / "r.dat")
    assert list(out) == names
    np.testing.assert_array_equal(out["Velocity_x"], data[:, 3])
    (tmp_path / "bad.dat").write_bytes(b"x" * 40)
    with pytest.raises(T.TrefftzError, match="bad.dat"):
        T.read_restart(tmp_path / "bad.dat")
    (tmp_path / "short.dat").write_bytes(raw[:-8])
    with pytest.raises(T.TrefftzError, match="shorter"):
        T.read_restart(tmp_path / "short.dat")


def test_command_exit_2_on_a_folder_without_solution(tmp_path, capsys):
    assert T.main([str(tmp_path)]) == 2
    assert "restart_flow.dat" in capsys.readouterr().err


def test_plot_draws_each_load_beside_its_ellipse(tmp_path):
    y = np.linspace(0, 3.6, 50)
    load = 0.5 * np.sqrt(np.clip(1 - (y / 3) ** 2, 0, None))
    rep = {"planes": [{"distance": 0.05, "y": y, "load": load, "CL_wake": 0.375, "e_wake": 0.98}]}
    T.plot([rep, rep], ["a", "b"], tmp_path / "w.png")
    assert (tmp_path / "w.png").stat().st_size > 10_000


def test_command_exit_2_on_a_folder_without_history(tmp_path, capsys):
    write_restart(tmp_path / "restart_flow.dat", ["x", "y", "z"], np.zeros((4, 3)))
    (tmp_path / "flow.cfg").write_text("AOA= 4.22\nMACH_NUMBER= 0.5\n")
    assert T.main([str(tmp_path)]) == 2
    assert "history" in capsys.readouterr().err
