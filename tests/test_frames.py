"""The contact Jacobian ``u = H v + w`` against rigid-body kinematics written out point by point.

Oracle: the relative velocity of the two material points at each contact,
``(v_b + omega_b x r_b) - (v_a + omega_a x r_a)`` in the frame ``[n, t1 (, t2)]``,
computed here contact by contact with no code of ``nscd.contact.frames``: the assembled
``H`` and ``w``, and the per-contact blocks the time step uses directly.
"""
from __future__ import annotations

import numpy as np
import pytest

import nscd.contact.frames as frames
from nscd.stepper import _dense_problem


def random_contacts(dim: int, m: int, n_bodies: int, rng: np.random.Generator) -> frames.Contacts:
    body_a = rng.integers(0, n_bodies, m)
    body_b = (body_a + rng.integers(1, n_bodies, m)) % n_bodies
    normal = rng.normal(size=(m, dim))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return frames.Contacts(body_a, body_b, rng.normal(size=(m, dim)), frames.tangent_frames(normal),
                           rng.normal(size=m), np.ones(m), np.zeros(m), np.zeros((m, 3), dtype=int))


def point_velocity(v: np.ndarray, centre: np.ndarray, point: np.ndarray) -> np.ndarray:
    """Velocity of a material point of a rigid body: v + omega x r (2D: omega scalar)."""
    r = point - centre
    if centre.size == 2:
        return v[:2] + v[2] * np.array([-r[1], r[0]])
    return v[:3] + np.cross(v[3:], r)


def kinematic_u(contacts: frames.Contacts, centres: np.ndarray, velocities: np.ndarray) -> np.ndarray:
    out = []
    for c in range(len(contacts)):
        a, b, x = contacts.body_a[c], contacts.body_b[c], contacts.point[c]
        rel = point_velocity(velocities[b], centres[b], x) - point_velocity(velocities[a], centres[a], x)
        out.append(contacts.frame[c] @ rel)
    return np.array(out).reshape(-1)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("dense", [True, False])
def test_jacobian_gives_the_relative_velocity_of_the_contact_points(dim, dense):
    """``dense``: ``H`` as the time step forms a small problem's, in its compiled stage
    (:func:`nscd.stepper._dense_problem`, from the same blocks); else CSR, as the large ones."""
    rng = np.random.default_rng(dim)
    nv = 3 if dim == 2 else 6
    n_bodies = 6
    dof_of_body = np.array([-1, 0, nv, -1, 2 * nv, 3 * nv])  # bodies 0 and 3 fixed or driven
    n_dofs = 4 * nv
    for _ in range(20):
        contacts = random_contacts(dim, int(rng.integers(0, 25)), n_bodies, rng)
        centres = rng.normal(size=(n_bodies, dim))
        velocities = rng.normal(size=(2, n_bodies, nv))  # two sets, as the stepper passes them
        H, w = frames.jacobian(contacts, centres, velocities, dof_of_body, n_dofs)
        H = H.toarray()
        if dense:
            blocks, _ = frames.contact_kinematics(contacts, centres, velocities[:1])
            m = len(contacts)
            H = _dense_problem(blocks, np.arange(m), contacts.body_a, contacts.body_b, dof_of_body, n_dofs,
                               np.ones(n_dofs), np.broadcast_to(np.eye(6), (n_dofs // 6, 6, 6)).copy(),
                               np.zeros(n_dofs), np.zeros((m, dim)))[0]
        for s in range(2):
            v = np.concatenate([velocities[s, b] for b in range(n_bodies) if dof_of_body[b] >= 0])
            expected = kinematic_u(contacts, centres, velocities[s])
            # a handful of products and sums of O(1) numbers: rounding only
            assert np.abs(H @ v + w[s] - expected).max(initial=0.0) <= 1e-13
            _, u = frames.contact_kinematics(contacts, centres, velocities[s:s + 1])
            assert np.abs(u.ravel() - expected).max(initial=0.0) <= 1e-13


def point_centripetal(v: np.ndarray, centre: np.ndarray, point: np.ndarray) -> np.ndarray:
    """Acceleration of a material point of a body turning at a constant rate, from rotation alone:
    omega x (omega x r), which in 2D is -omega^2 r."""
    r = point - centre
    if centre.size == 2:
        return -v[2] ** 2 * r
    return np.cross(v[3:], np.cross(v[3:], r))


@pytest.mark.parametrize("dim", [2, 3])
def test_centripetal_term_is_the_relative_acceleration_from_rotation(dim):
    """The second-order gap term of the step: point b's centripetal acceleration minus point a's,
    in the contact frame, written out contact by contact."""
    rng = np.random.default_rng(10 + dim)
    nv = 3 if dim == 2 else 6
    for _ in range(20):
        contacts = random_contacts(dim, int(rng.integers(0, 25)), 6, rng)
        centres = rng.normal(size=(6, dim))
        velocities = rng.normal(size=(6, nv))
        expected = np.array([contacts.frame[c] @ (
            point_centripetal(velocities[contacts.body_b[c]], centres[contacts.body_b[c]], contacts.point[c])
            - point_centripetal(velocities[contacts.body_a[c]], centres[contacts.body_a[c]], contacts.point[c]))
            for c in range(len(contacts))]).reshape(len(contacts), dim)
        got = frames.centripetal_acceleration(contacts, centres, velocities)
        assert got.shape == (len(contacts), dim)
        # products of a few O(1) numbers, summed in another order: rounding only
        assert np.abs(got - expected).max(initial=0.0) <= 1e-12 * (1.0 + np.abs(expected).max(initial=0.0))


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_3d_frame_turns_continuously_with_a_normal_near_a_world_axis(axis):
    """A normal a hair off a world axis, its two small components in either order and sign:
    the frames differ by the normals' difference (continuity), not by a quarter turn.

    Why it matters: a step's tangential impulses warm-start the next step in this frame; a
    bed joint's normal wobbling around z by 1e-9 rad must not turn its friction by 90 deg.
    """
    rng = np.random.default_rng(axis)
    normals = np.zeros((200, 3))
    normals[:, axis] = rng.choice([-1.0, 1.0])
    others = [d for d in range(3) if d != axis]
    normals[:, others] = rng.uniform(-1e-9, 1e-9, size=(200, 2))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    frame = frames.tangent_frames(normals)
    # orthonormal and right-handed
    np.testing.assert_allclose(frame @ frame.transpose(0, 2, 1), np.broadcast_to(np.eye(3), frame.shape), atol=1e-15)
    np.testing.assert_allclose(np.linalg.det(frame), 1.0, atol=1e-15)
    # every frame within a few 1e-9 of the first (a flip would differ by sqrt(2))
    assert np.abs(frame - frame[0]).max() < 1e-8


def test_3d_frame_is_defined_for_every_direction():
    """Any unit normal (the diagonals too, where all components are 1/sqrt(3)): an orthonormal frame on it."""
    rng = np.random.default_rng(5)
    normals = np.vstack([rng.normal(size=(500, 3)), [[1.0, 1.0, 1.0], [-1.0, 1.0, -1.0], [0.6, 0.8, 0.0]]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    frame = frames.tangent_frames(normals)
    np.testing.assert_allclose(frame[:, 0], normals, atol=0.0)
    np.testing.assert_allclose(frame @ frame.transpose(0, 2, 1), np.broadcast_to(np.eye(3), frame.shape), atol=1e-14)
