"""The rotation math of ffdcli.volume.frames, each derivative against central differences of its own."""

from __future__ import annotations

import numpy as np

from ffdcli.volume.frames import (
    planar_rotation_derivative,
    polar_rotation_derivative,
    rotations_from_deformation_gradient,
    surface_frame_gradient,
    surface_frame_gradient_jvp,
)

H = 1e-6
# central differences: truncation ~ h^2 |f'''| ~ 1e-12, rounding ~ eps / h ~ 1e-10
TOL = 1e-8


def random_F(rng, n, scale=0.3):
    return np.eye(3) + scale * rng.normal(size=(n, 3, 3))


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_polar_rotation_is_a_proper_rotation_and_its_derivative_matches_fd():
    rng = np.random.default_rng(0)
    F = random_F(rng, 40)
    F = F[np.linalg.det(F) > 0.2]              # away from the singular F where R jumps
    dF = rng.normal(size=F.shape)
    R = rotations_from_deformation_gradient(F)
    np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-13)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-13)
    fd = (rotations_from_deformation_gradient(F + H * dF) - rotations_from_deformation_gradient(F - H * dF)) / (2 * H)
    np.testing.assert_allclose(polar_rotation_derivative(F, R, dF), fd, rtol=0, atol=TOL)


def test_planar_rotation_derivative_matches_fd():
    rng = np.random.default_rng(1)
    for axis in (0, 1, 2):
        F = random_F(rng, 30)
        dF = rng.normal(size=F.shape)
        f = lambda G, k=axis: rotations_from_deformation_gradient(G, axis=k)  # noqa: E731
        fd = (f(F + H * dF) - f(F - H * dF)) / (2 * H)
        got = planar_rotation_derivative(F, dF, axis)
        np.testing.assert_allclose(got, fd, rtol=0, atol=TOL)
        assert np.all(got[:, axis, :] == 0) and np.all(got[:, :, axis] == 0)


def test_surface_frame_gradient_maps_the_normal_to_the_deformed_normal_and_its_jvp_matches_fd():
    rng = np.random.default_rng(2)
    F = random_F(rng, 30)
    n0 = unit(rng.normal(size=(30, 3)))
    Fs = surface_frame_gradient(F, n0)
    n1 = np.einsum("sij,sj->si", Fs, n0)
    np.testing.assert_allclose(np.linalg.norm(n1, axis=1), 1.0, atol=1e-13)
    # on the tangent plane F_s is F
    t = unit(np.cross(n0, rng.normal(size=(30, 3))))
    np.testing.assert_allclose(np.einsum("sij,sj->si", Fs, t), np.einsum("sij,sj->si", F, t), atol=1e-13)
    dF = rng.normal(size=F.shape)
    fd = (surface_frame_gradient(F + H * dF, n0) - surface_frame_gradient(F - H * dF, n0)) / (2 * H)
    np.testing.assert_allclose(surface_frame_gradient_jvp(F, n0, dF), fd, rtol=0, atol=TOL)


def test_surface_frame_gradient_2d_jvp_matches_fd():
    rng = np.random.default_rng(3)
    F = np.eye(2) + 0.3 * rng.normal(size=(20, 2, 2))
    n0 = unit(rng.normal(size=(20, 2)))
    dF = rng.normal(size=F.shape)
    fd = (surface_frame_gradient(F + H * dF, n0) - surface_frame_gradient(F - H * dF, n0)) / (2 * H)
    np.testing.assert_allclose(surface_frame_gradient_jvp(F, n0, dF), fd, rtol=0, atol=TOL)


def test_the_chain_polar_of_the_surface_frame_matches_fd():
    """What the API differentiates: R(F_s(F)) in a direction dF."""
    rng = np.random.default_rng(4)
    F = random_F(rng, 30, 0.15)
    n0 = unit(rng.normal(size=(30, 3)))
    dF = rng.normal(size=F.shape)
    Fs = surface_frame_gradient(F, n0)
    R = rotations_from_deformation_gradient(Fs)
    got = polar_rotation_derivative(Fs, R, surface_frame_gradient_jvp(F, n0, dF))
    f = lambda G: rotations_from_deformation_gradient(surface_frame_gradient(G, n0))  # noqa: E731
    fd = (f(F + H * dF) - f(F - H * dF)) / (2 * H)
    np.testing.assert_allclose(got, fd, rtol=0, atol=TOL)
