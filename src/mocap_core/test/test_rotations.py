"""Tests for mocap_core.rotations against scipy.spatial.transform.Rotation."""

import itertools
import warnings

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation, Slerp

from mocap_core import rotations as rot

TAIT_BRYAN = [''.join(p) for p in itertools.permutations('xyz')]
PROPER = [a + b + a for a in 'xyz' for b in 'xyz' if a != b]
ALL_ORDERS = [o for base in TAIT_BRYAN + PROPER for o in (base.upper(), base)]
TOL = 1e-10


def random_quats(n, seed=0):
    return Rotation.random(n, random_state=seed).as_quat()


def assert_quat_close(q1, q2, atol=TOL):
    """Quaternions equal up to the global sign."""
    q1, q2 = np.asarray(q1), np.asarray(q2)
    sign = np.where(np.sum(q1 * q2, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    np.testing.assert_allclose(q1, sign * q2, atol=atol, rtol=0)


def special_rotvecs():
    """Rotation vectors near 0, at the Taylor threshold, near and exactly at pi."""
    rng = np.random.default_rng(3)
    axes = rng.normal(size=(8, 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    angles = np.array([0.0, 1e-12, 1e-8, 9.99e-4, 1.001e-3, 0.5, np.pi - 1e-7, np.pi])
    rv = axes * angles[:, None]
    axis_aligned = np.array([[np.pi, 0, 0], [0, np.pi, 0], [0, 0, np.pi], [0, 0, 0]])
    return np.concatenate([rv, axis_aligned])


# --------------------------------------------------------------------------
# quaternion <-> matrix
# --------------------------------------------------------------------------
def test_quat_to_matrix_matches_scipy():
    q = random_quats(200)
    np.testing.assert_allclose(rot.quat_to_matrix(q), Rotation.from_quat(q).as_matrix(), atol=TOL)
    # non-unit quaternions describe the same rotation
    scale = np.linspace(0.1, 5.0, 200)[:, None]
    np.testing.assert_allclose(rot.quat_to_matrix(q * scale), Rotation.from_quat(q).as_matrix(),
                               atol=TOL)


def test_matrix_to_quat_matches_scipy_all_angles():
    rv = np.concatenate([Rotation.random(300, random_state=1).as_rotvec(), special_rotvecs()])
    R = Rotation.from_rotvec(rv).as_matrix()
    q = rot.matrix_to_quat(R)
    assert q.shape == (len(rv), 4)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=TOL)
    assert np.all(q[:, 3] >= 0), 'matrix_to_quat must return canonical (w >= 0) quaternions'
    assert_quat_close(q, Rotation.from_matrix(R).as_quat(), atol=1e-9)
    np.testing.assert_allclose(rot.quat_to_matrix(q), R, atol=TOL)


def test_matrix_to_quat_exact_180_degrees():
    # diag matrices of 180 deg rotations: trace = -1, w = 0
    for axis in range(3):
        R = -np.eye(3)
        R[axis, axis] = 1.0
        q = rot.matrix_to_quat(R)
        expected = np.zeros(4)
        expected[axis] = 1.0
        assert_quat_close(q, expected, atol=1e-15)


# --------------------------------------------------------------------------
# axis-angle
# --------------------------------------------------------------------------
def test_axis_angle_to_quat_and_matrix_match_scipy():
    rv = np.concatenate([Rotation.random(200, random_state=2).as_rotvec(), special_rotvecs(),
                         np.random.default_rng(0).normal(size=(50, 3)) * 4.0])  # also angles > pi
    assert_quat_close(rot.axis_angle_to_quat(rv), Rotation.from_rotvec(rv).as_quat(), atol=1e-12)
    np.testing.assert_allclose(rot.axis_angle_to_matrix(rv), Rotation.from_rotvec(rv).as_matrix(),
                               atol=1e-12)


def test_quat_to_axis_angle_matches_scipy():
    rv = np.concatenate([Rotation.random(200, random_state=4).as_rotvec(), special_rotvecs()])
    q = Rotation.from_rotvec(rv).as_quat()
    out = rot.quat_to_axis_angle(q)
    angle = np.linalg.norm(rv, axis=-1)
    ref = Rotation.from_quat(q).as_rotvec()
    not_pi = angle < np.pi - 1e-6
    np.testing.assert_allclose(out[not_pi], ref[not_pi], atol=1e-12, rtol=0)
    # at pi the axis sign is ambiguous: compare angle and the rotation itself
    np.testing.assert_allclose(np.linalg.norm(out, axis=-1), angle, atol=1e-9)
    np.testing.assert_allclose(rot.axis_angle_to_matrix(out), Rotation.from_rotvec(rv).as_matrix(),
                               atol=1e-12)
    # -q is the same rotation
    np.testing.assert_allclose(rot.quat_to_axis_angle(-q[not_pi]), ref[not_pi], atol=1e-12)
    # tiny rotations are exact to relative precision (no cancellation)
    tiny = np.array([[1e-13, -2e-13, 3e-13]])
    np.testing.assert_allclose(rot.quat_to_axis_angle(rot.axis_angle_to_quat(tiny)), tiny,
                               rtol=1e-12, atol=0)


def test_matrix_axis_angle_roundtrip():
    rv = np.concatenate([Rotation.random(100, random_state=5).as_rotvec(), special_rotvecs()])
    R = rot.axis_angle_to_matrix(rv)
    back = rot.matrix_to_axis_angle(R)
    np.testing.assert_allclose(rot.axis_angle_to_matrix(back), R, atol=1e-12)
    small = np.linalg.norm(rv, axis=-1) < 3.0
    np.testing.assert_allclose(back[small], rv[small], atol=1e-12)


# --------------------------------------------------------------------------
# 6D
# --------------------------------------------------------------------------
def test_rot6d_roundtrip_and_layout():
    q = random_quats(100, seed=6)
    R = Rotation.from_quat(q).as_matrix()
    d = rot.matrix_to_rot6d(R)
    assert d.shape == (100, 6)
    np.testing.assert_array_equal(d[:, :3], R[:, :, 0])
    np.testing.assert_array_equal(d[:, 3:], R[:, :, 1])
    np.testing.assert_allclose(rot.rot6d_to_matrix(d), R, atol=TOL)
    np.testing.assert_allclose(rot.quat_to_rot6d(q), d, atol=TOL)
    assert_quat_close(rot.rot6d_to_quat(d), q)


def test_rot6d_gram_schmidt_of_arbitrary_input():
    d = np.random.default_rng(7).normal(size=(50, 6))
    R = rot.rot6d_to_matrix(d)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    # first column is the direction of d[:3]; second lies in span(d[:3], d[3:])
    first = d[:, :3] / np.linalg.norm(d[:, :3], axis=-1, keepdims=True)
    np.testing.assert_allclose(R[:, :, 0], first, atol=1e-12)
    normal = np.cross(d[:, :3], d[:, 3:])
    np.testing.assert_allclose(np.sum(normal * R[:, :, 1], axis=-1), 0.0, atol=1e-12)
    assert np.all(np.sum(d[:, 3:] * R[:, :, 1], axis=-1) > 0)


# --------------------------------------------------------------------------
# Euler angles
# --------------------------------------------------------------------------
@pytest.mark.parametrize('order', ALL_ORDERS)
def test_euler_matches_scipy(order):
    rng = np.random.default_rng(8)
    R_ref = Rotation.random(100, random_state=9)
    angles = R_ref.as_euler(order)
    np.testing.assert_allclose(rot.euler_to_matrix(angles, order),
                               Rotation.from_euler(order, angles).as_matrix(), atol=1e-12)
    assert_quat_close(rot.euler_to_quat(angles, order),
                      Rotation.from_euler(order, angles).as_quat(), atol=1e-12)
    np.testing.assert_allclose(rot.matrix_to_euler(R_ref.as_matrix(), order), angles, atol=1e-9)
    np.testing.assert_allclose(rot.quat_to_euler(R_ref.as_quat(), order), angles, atol=1e-9)
    # arbitrary (out of range) angles: forward must still match; backward round-trips the matrix
    wild = rng.uniform(-7, 7, size=(100, 3))
    R_wild = rot.euler_to_matrix(wild, order)
    np.testing.assert_allclose(R_wild, Rotation.from_euler(order, wild).as_matrix(), atol=1e-12)
    back = rot.matrix_to_euler(R_wild, order)
    np.testing.assert_allclose(rot.euler_to_matrix(back, order), R_wild, atol=1e-12)


def test_euler_definition_explicit():
    a, b, c = 0.3, -0.7, 1.9

    def elem(axis, ang):
        return Rotation.from_rotvec(np.eye(3)[axis] * ang).as_matrix()
    np.testing.assert_allclose(rot.euler_to_matrix([a, b, c], 'ZYX'),
                               elem(2, a) @ elem(1, b) @ elem(0, c), atol=1e-15)
    np.testing.assert_allclose(rot.euler_to_matrix([a, b, c], 'xyz'),
                               elem(2, c) @ elem(1, b) @ elem(0, a), atol=1e-15)
    np.testing.assert_allclose(rot.euler_to_matrix([a, b, c], 'ZXZ'),
                               elem(2, a) @ elem(0, b) @ elem(2, c), atol=1e-15)


@pytest.mark.parametrize('order', ALL_ORDERS)
def test_euler_gimbal_lock(order):
    proper = order[0].lower() == order[2].lower()
    middles = [0.0, np.pi, 1e-12, np.pi - 1e-12] if proper else [np.pi / 2, -np.pi / 2,
                                                                  np.pi / 2 - 1e-12]
    rng = np.random.default_rng(10)
    angles = []
    for m in middles:
        for _ in range(5):
            a, c = rng.uniform(-np.pi, np.pi, size=2)
            angles.append([a, m, c])
    angles = np.array(angles)
    R = rot.euler_to_matrix(angles, order)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        np.testing.assert_allclose(R, Rotation.from_euler(order, angles).as_matrix(), atol=1e-12)
    out = rot.matrix_to_euler(R, order)
    assert np.all(np.isfinite(out))
    np.testing.assert_allclose(rot.euler_to_matrix(out, order), R, atol=1e-10)
    np.testing.assert_array_equal(out[:, 2], 0.0)  # SciPy's convention: last angle := 0
    exact = np.isin(angles[:, 1], [0.0, np.pi, np.pi / 2, -np.pi / 2])
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        ref = Rotation.from_matrix(R[exact]).as_euler(order)
    np.testing.assert_allclose(np.cos(out[exact] - ref), 1.0, atol=1e-12)  # same angles mod 2 pi
    q = rot.euler_to_quat(out, order)
    np.testing.assert_allclose(rot.quat_to_matrix(q), R, atol=1e-10)
    # near (but not in) lock, still reconstructs
    eps_angles = angles.copy()
    eps_angles[:, 1] += 1e-6 if not proper else 0.0
    if proper:
        eps_angles[:, 1] = np.where(eps_angles[:, 1] < 1, 1e-6, np.pi - 1e-6)
    R2 = rot.euler_to_matrix(eps_angles, order)
    np.testing.assert_allclose(rot.euler_to_matrix(rot.matrix_to_euler(R2, order), order), R2,
                               atol=1e-9)


@pytest.mark.parametrize('bad', ['XY', 'xyzx', 'XyZ', 'XXY', 'xyy', 'abc', 5])
def test_euler_invalid_order(bad):
    with pytest.raises(ValueError):
        rot.euler_to_matrix(np.zeros(3), bad)
    with pytest.raises(ValueError):
        rot.matrix_to_euler(np.eye(3), bad)


# --------------------------------------------------------------------------
# quaternion algebra
# --------------------------------------------------------------------------
def test_quat_multiply_is_scipy_composition():
    a, b = random_quats(100, 11), random_quats(100, 12)
    ref = (Rotation.from_quat(a) * Rotation.from_quat(b)).as_quat()
    assert_quat_close(rot.quat_multiply(a, b), ref)
    np.testing.assert_allclose(rot.quat_to_matrix(rot.quat_multiply(a, b)),
                               rot.quat_to_matrix(a) @ rot.quat_to_matrix(b), atol=TOL)
    # broadcasting (1 x N) against (N)
    assert_quat_close(rot.quat_multiply(a[:1], b),
                      (Rotation.from_quat(a[0]) * Rotation.from_quat(b)).as_quat())


def test_quat_rotate_conjugate_inverse():
    q = random_quats(100, 13)
    v = np.random.default_rng(14).normal(size=(100, 3))
    np.testing.assert_allclose(rot.quat_rotate(q, v), Rotation.from_quat(q).apply(v), atol=TOL)
    np.testing.assert_allclose(rot.quat_rotate(3.0 * q, v), Rotation.from_quat(q).apply(v),
                               atol=TOL)
    np.testing.assert_allclose(rot.quat_conjugate(q), q * np.array([-1, -1, -1, 1]))
    assert_quat_close(rot.quat_multiply(q, rot.quat_inverse(q)), np.tile([0, 0, 0, 1.0], (100, 1)))
    qs = 2.5 * q
    np.testing.assert_allclose(rot.quat_multiply(qs, rot.quat_inverse(qs)),
                               np.tile([0, 0, 0, 1.0], (100, 1)), atol=TOL)
    np.testing.assert_allclose(rot.quat_normalize(qs), q, atol=TOL)


def test_quat_identity_and_canonical():
    ident = rot.quat_identity()
    assert isinstance(ident, np.ndarray) and ident.dtype == np.float64
    np.testing.assert_array_equal(ident, [0, 0, 0, 1])
    assert rot.quat_identity((2, 3)).shape == (2, 3, 4)
    assert rot.quat_identity(5).shape == (5, 4)
    like = torch.zeros(2, dtype=torch.float32)
    t = rot.quat_identity((4,), like=like)
    assert isinstance(t, torch.Tensor) and t.dtype == torch.float32 and t.shape == (4, 4)
    assert torch.equal(t[2], torch.tensor([0.0, 0.0, 0.0, 1.0]))
    q = random_quats(50, 15)
    c = rot.quat_canonical(-q)
    assert np.all(c[:, 3] >= 0)
    assert_quat_close(c, q, atol=0)


def test_quat_angle():
    a, b = random_quats(100, 16), random_quats(100, 17)
    ref = (Rotation.from_quat(a).inv() * Rotation.from_quat(b)).magnitude()
    np.testing.assert_allclose(rot.quat_angle(a, b), ref, atol=1e-12)
    np.testing.assert_allclose(rot.quat_angle(a, -b), ref, atol=1e-12)
    # robust near 0 (acos would lose everything) and at pi
    h = np.pi / np.sqrt(2)
    rv = np.array([[1e-9, 0, 0], [0, 2e-11, 0], [0, 0, np.pi], [h, h, 0]])
    d = Rotation.from_rotvec(rv).as_quat()
    ang = rot.quat_angle(np.tile(a[:1], (4, 1)), rot.quat_multiply(a[:1], d))
    np.testing.assert_allclose(ang, np.linalg.norm(rv, axis=-1), rtol=1e-6, atol=1e-15)
    assert rot.quat_angle(a[0], a[0]) < 1e-15


def test_quat_slerp_vs_scipy():
    a, b = random_quats(30, 18), random_quats(30, 19)
    # endpoints
    assert_quat_close(rot.quat_slerp(a, b, 0.0), a)
    assert_quat_close(rot.quat_slerp(a, b, 1.0), b)
    ts = np.array([0.0, 0.25, 0.5, 0.8, 1.0])
    for n in range(len(a)):
        s = Slerp([0.0, 1.0], Rotation.from_quat(np.stack([a[n], b[n]])))
        ref = s(ts).as_quat()
        # t broadcast against a single pair
        out = rot.quat_slerp(a[n], b[n], ts)
        assert out.shape == (5, 4)
        assert_quat_close(out, ref, atol=1e-10)
        # shortest path regardless of the sign of b
        assert_quat_close(rot.quat_slerp(a[n], -b[n], ts), ref, atol=1e-10)
    # midpoint: equal angle to both ends, half the total
    mid = rot.quat_slerp(a, b, 0.5)
    np.testing.assert_allclose(rot.quat_angle(a, mid), rot.quat_angle(mid, b), atol=1e-10)
    np.testing.assert_allclose(2 * rot.quat_angle(a, mid), rot.quat_angle(a, b), atol=1e-10)


def test_quat_slerp_nearly_parallel():
    a = random_quats(1, 20)[0]
    tiny = Rotation.from_rotvec([1e-9, -2e-9, 0.5e-9]).as_quat()
    b = rot.quat_multiply(a, tiny)
    out = rot.quat_slerp(a, b, np.array([0.0, 0.5, 1.0]))
    assert np.all(np.isfinite(out))
    assert_quat_close(out[0], a, atol=1e-12)
    assert_quat_close(out[2], b, atol=1e-12)
    half = rot.quat_multiply(a, Rotation.from_rotvec([0.5e-9, -1e-9, 0.25e-9]).as_quat())
    assert_quat_close(out[1], half, atol=1e-12)
    assert_quat_close(rot.quat_slerp(a, a, 0.3), a, atol=1e-15)
    # small but not negligible angles must be true slerp (nlerp would be off by ~angle^3)
    for ang in [1e-4, 1e-3, 1e-2, 0.05]:
        b = rot.quat_multiply(a, Rotation.from_rotvec([0.0, ang, 0.0]).as_quat())
        ref = Slerp([0.0, 1.0], Rotation.from_quat(np.stack([a, b])))([0.3]).as_quat()[0]
        assert_quat_close(rot.quat_slerp(a, b, 0.3), ref, atol=1e-13)


# --------------------------------------------------------------------------
# misc
# --------------------------------------------------------------------------
def test_skew():
    rng = np.random.default_rng(21)
    v, u = rng.normal(size=(2, 7, 3))
    np.testing.assert_allclose((rot.skew(v) @ u[..., None])[..., 0], np.cross(v, u), atol=1e-14)
    S = rot.skew(v)
    np.testing.assert_array_equal(S, -np.swapaxes(S, -1, -2))


def test_closest_yaw():
    """The yaw of a rotation about z is itself; tilting it about x or y by up to 30 deg keeps
    the nearest turn about z within a few degrees of it, and a tilt alone gives 0."""
    for yaw in (-3.0, -1.2, 0.0, 0.4, 2.9):
        Rz = Rotation.from_euler('z', yaw).as_matrix()
        assert rot.closest_yaw(Rz) == pytest.approx(yaw, abs=1e-12)
        for axis in 'xy':
            tilt = Rotation.from_euler(axis, 0.5).as_matrix()
            assert rot.closest_yaw(tilt) == pytest.approx(0.0, abs=1e-12)
            got = rot.closest_yaw(Rz @ Rotation.from_euler(axis, 0.2).as_matrix())
            assert abs((got - yaw + np.pi) % (2 * np.pi) - np.pi) < 0.05


def test_quat_from_two_vectors():
    rng = np.random.default_rng(22)
    a = rng.normal(size=(100, 3)) * rng.uniform(0.1, 10, size=(100, 1))
    b = rng.normal(size=(100, 3))
    special_a = np.array([[1, 0, 0], [0, 0, 2.0], [1, 2, 3], [1, 2, 3], [0.3, -0.2, 0.9],
                          [1, 0, 0]])
    special_b = np.array([[-1, 0, 0], [0, 0, -1.0], [-2, -4, -6], [1, 2, 3], [-0.3, 0.2, -0.9],
                          [1, 1e-9, 0]])
    a = np.concatenate([a, special_a])
    b = np.concatenate([b, special_b])
    q = rot.quat_from_two_vectors(a, b)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-14)
    ua = a / np.linalg.norm(a, axis=-1, keepdims=True)
    ub = b / np.linalg.norm(b, axis=-1, keepdims=True)
    np.testing.assert_allclose(rot.quat_rotate(q, ua), ub, atol=1e-12)
    # minimal: rotation angle == angle between the vectors, axis perpendicular to both
    expected_angle = np.arctan2(np.linalg.norm(np.cross(ua, ub), axis=-1),
                                np.sum(ua * ub, axis=-1))
    angle = np.linalg.norm(rot.quat_to_axis_angle(q), axis=-1)
    np.testing.assert_allclose(angle, expected_angle, atol=1e-9)
    np.testing.assert_allclose(np.sum(rot.quat_to_axis_angle(q) * ua, axis=-1), 0.0, atol=1e-9)


# --------------------------------------------------------------------------
# torch / numpy parity, gradients, shapes, immutability
# --------------------------------------------------------------------------
def _inputs(seed=23, shape=(2, 3)):
    rng = np.random.default_rng(seed)
    n = int(np.prod(shape))
    q = Rotation.random(n, random_state=seed).as_quat().reshape(shape + (4,))
    R = rot.quat_to_matrix(q)
    return {
        'q': q,
        'q2': Rotation.random(n, random_state=seed + 1).as_quat().reshape(shape + (4,)),
        'R': R,
        'v': rng.normal(size=shape + (3,)),
        'd6': rng.normal(size=shape + (6,)),
        'e': rng.uniform(-1.2, 1.2, size=shape + (3,)),
        't': rng.uniform(0, 1, size=shape),
    }


CASES = {
    'quat_normalize': (rot.quat_normalize, ['q']),
    'quat_conjugate': (rot.quat_conjugate, ['q']),
    'quat_inverse': (rot.quat_inverse, ['q']),
    'quat_multiply': (rot.quat_multiply, ['q', 'q2']),
    'quat_rotate': (rot.quat_rotate, ['q', 'v']),
    'quat_canonical': (rot.quat_canonical, ['q']),
    'quat_angle': (rot.quat_angle, ['q', 'q2']),
    'quat_slerp': (rot.quat_slerp, ['q', 'q2', 't']),
    'quat_to_matrix': (rot.quat_to_matrix, ['q']),
    'matrix_to_quat': (rot.matrix_to_quat, ['R']),
    'axis_angle_to_quat': (rot.axis_angle_to_quat, ['v']),
    'quat_to_axis_angle': (rot.quat_to_axis_angle, ['q']),
    'axis_angle_to_matrix': (rot.axis_angle_to_matrix, ['v']),
    'matrix_to_axis_angle': (rot.matrix_to_axis_angle, ['R']),
    'matrix_to_rot6d': (rot.matrix_to_rot6d, ['R']),
    'rot6d_to_matrix': (rot.rot6d_to_matrix, ['d6']),
    'quat_to_rot6d': (rot.quat_to_rot6d, ['q']),
    'rot6d_to_quat': (rot.rot6d_to_quat, ['d6']),
    'euler_to_matrix_ZYX': (lambda e: rot.euler_to_matrix(e, 'ZYX'), ['e']),
    'euler_to_matrix_xzx': (lambda e: rot.euler_to_matrix(e, 'xzx'), ['e']),
    'matrix_to_euler_XYZ': (lambda R: rot.matrix_to_euler(R, 'XYZ'), ['R']),
    'matrix_to_euler_zyz': (lambda R: rot.matrix_to_euler(R, 'zyz'), ['R']),
    'euler_to_quat_YXZ': (lambda e: rot.euler_to_quat(e, 'YXZ'), ['e']),
    'quat_to_euler_yzy': (lambda q: rot.quat_to_euler(q, 'yzy'), ['q']),
    'skew': (rot.skew, ['v']),
    'quat_from_two_vectors': (rot.quat_from_two_vectors, ['v', 'e']),
}

OUT_TAIL = {'quat_angle': 0, 'quat_to_matrix': 2, 'axis_angle_to_matrix': 2, 'rot6d_to_matrix': 2,
            'euler_to_matrix_ZYX': 2, 'euler_to_matrix_xzx': 2, 'skew': 2}


@pytest.mark.parametrize('name', sorted(CASES))
def test_torch_matches_numpy_and_shapes(name):
    fn, keys = CASES[name]
    shape = (2, 3, 4)
    inp = _inputs(shape=shape)
    args_np = [inp[k] for k in keys]
    copies_np = [a.copy() for a in args_np]
    out_np = fn(*args_np)
    assert isinstance(out_np, np.ndarray)
    assert out_np.dtype == np.float64
    tail = OUT_TAIL.get(name, 1)
    assert out_np.shape[:len(shape)] == shape and out_np.ndim == len(shape) + tail
    for a, c in zip(args_np, copies_np):
        np.testing.assert_array_equal(a, c)  # inputs untouched
    args_t = [torch.tensor(a, dtype=torch.float64) for a in args_np]
    copies_t = [a.clone() for a in args_t]
    out_t = fn(*args_t)
    assert isinstance(out_t, torch.Tensor) and out_t.dtype == torch.float64
    np.testing.assert_allclose(out_t.numpy(), out_np, atol=1e-12, rtol=0)
    for a, c in zip(args_t, copies_t):
        assert torch.equal(a, c)


def test_float32_torch_stays_float32():
    q = torch.tensor(random_quats(10, 24), dtype=torch.float32)
    assert rot.quat_to_matrix(q).dtype == torch.float32
    R = rot.quat_to_matrix(q)
    assert rot.matrix_to_euler(R, 'XYZ').dtype == torch.float32
    assert rot.quat_slerp(q, q.flip(0), 0.5).dtype == torch.float32


def _t(x):
    return torch.tensor(x, dtype=torch.float64, requires_grad=True)


def test_gradcheck_quat_to_matrix():
    q = _t(random_quats(4, 25) * np.array([[1.0], [2.0], [0.5], [1.3]]))
    assert torch.autograd.gradcheck(rot.quat_to_matrix, (q,))


def test_gradcheck_rot6d_to_matrix():
    d = _t(np.random.default_rng(26).normal(size=(4, 6)))
    assert torch.autograd.gradcheck(rot.rot6d_to_matrix, (d,))


def test_gradcheck_axis_angle_to_quat_including_zero():
    rv = np.concatenate([np.random.default_rng(27).normal(size=(3, 3)), np.zeros((1, 3)),
                         [[1e-5, 0, -2e-5]]])
    v = _t(rv)
    assert torch.autograd.gradcheck(rot.axis_angle_to_quat, (v,))
    z = _t(np.zeros(3))
    rot.axis_angle_to_quat(z).sum().backward()
    assert torch.all(torch.isfinite(z.grad))
    # d(xyz)/dv = I/2 and d(w)/dv = 0 at the origin
    np.testing.assert_allclose(z.grad.numpy(), 0.5 * np.ones(3), atol=1e-12)
    z2 = _t(np.zeros((2, 3)))
    rot.axis_angle_to_matrix(z2).sum().backward()
    assert torch.all(torch.isfinite(z2.grad))


def test_gradcheck_matrix_to_quat():
    # include rotations where each Shepperd candidate is selected (large x, y, z and w)
    rv = np.array([[0.3, -0.2, 0.1], [3.0, 0.2, -0.1], [0.1, 2.9, 0.3], [-0.2, 0.1, 3.0]])
    R = _t(Rotation.from_rotvec(rv).as_matrix())
    assert torch.autograd.gradcheck(rot.matrix_to_quat, (R,))


def test_gradcheck_other_functions():
    q = _t(random_quats(3, 28))
    q2 = _t(random_quats(3, 29))
    t = _t(np.array([0.2, 0.5, 0.9]))
    assert torch.autograd.gradcheck(rot.quat_to_axis_angle, (q,))
    assert torch.autograd.gradcheck(rot.quat_slerp, (q, q2, t))
    assert torch.autograd.gradcheck(lambda R: rot.matrix_to_euler(R, 'ZXY'),
                                    (_t(Rotation.from_quat(random_quats(3, 30)).as_matrix()),))
    # finite gradients in gimbal lock thanks to the guarded atan2 branches
    for order, mid in [('XYZ', np.pi / 2), ('zyx', -np.pi / 2), ('ZXZ', 0.0), ('yxy', np.pi)]:
        R_lock = _t(rot.euler_to_matrix(np.array([[0.3, mid, -0.4]]), order))
        rot.matrix_to_euler(R_lock, order).sum().backward()
        assert torch.all(torch.isfinite(R_lock.grad)), order
    # and away from lock where the unused lock branch sees atan2(0, 0)
    R_free = _t(np.array([[[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]))  # exact Rz(90)
    assert torch.autograd.gradcheck(lambda R: rot.matrix_to_euler(R, 'XYZ'), (R_free,))


def test_shape_validation():
    with pytest.raises(ValueError):
        rot.quat_to_matrix(np.zeros((5, 3)))
    with pytest.raises(ValueError):
        rot.matrix_to_quat(np.zeros((5, 4, 4)))
    with pytest.raises(ValueError):
        rot.rot6d_to_matrix(np.zeros((5, 5)))
