"""Rotation utilities shared by NumPy and PyTorch code (one implementation).

Every function is written against the Python array API through
``array_api_compat.array_namespace``: NumPy inputs give NumPy outputs, torch
tensors give torch tensors (on the same device, with autograd intact).  No
function modifies its inputs.  Python scalars / lists are accepted and treated
as NumPy float64; integer arrays are promoted to float64.

Conventions
-----------
* Quaternions are ``(x, y, z, w)`` -- **scalar last**, always (the same layout
  as ``scipy.spatial.transform.Rotation.as_quat()``).  Functions that build a
  rotation from a quaternion accept non-unit quaternions (they use the
  rotation of ``q / |q|``); a zero quaternion gives NaN.
* Rotation matrices have shape ``(..., 3, 3)`` and act on column vectors:
  ``v' = R @ v``.  A quaternion ``q`` and its matrix ``R`` satisfy
  ``quat_rotate(q, v) == R @ v``.
* ``quat_multiply(a, b)`` is the Hamilton product ``a * b``: the rotation that
  applies ``b`` first, then ``a`` (matches ``quat_to_matrix(a) @ quat_to_matrix(b)``
  and SciPy's ``Rotation(a) * Rotation(b)``).
* Angles are in radians.  Axis-angle values are rotation vectors
  ``axis * angle`` of shape ``(..., 3)``.
* The 6D representation (Zhou et al., CVPR 2019) is the first two *columns*
  of ``R`` concatenated: ``[R[:, 0], R[:, 1]]`` with shape ``(..., 6)``.
* Euler ``order`` strings follow SciPy: three letters from ``xyz``; UPPER
  case is intrinsic (``'ZYX'``: ``R = Rz(a) @ Ry(b) @ Rx(c)`` for angles
  ``(a, b, c)``), lower case is extrinsic (``'xyz'``: ``R = Rz(c) @ Ry(b) @ Rx(a)``).
  All 12 sequences are supported: Tait--Bryan (three distinct axes, middle
  angle in ``[-pi/2, pi/2]``) and proper Euler (first axis == third axis,
  middle angle in ``[0, pi]``); the other two angles are in ``[-pi, pi]``.
  In gimbal lock the last angle of the sequence is set to 0 (as SciPy does).

All functions are batched over arbitrary leading dimensions ``...``.
"""

from __future__ import annotations

from typing import Any, Sequence, Tuple, Union

import numpy as np
from array_api_compat import array_namespace, device as _device, is_array_api_obj

Array = Any
"""Any array-API array: ``numpy.ndarray`` or ``torch.Tensor``."""

__all__ = [
    'Array',
    'quat_normalize',
    'quat_conjugate',
    'quat_inverse',
    'quat_multiply',
    'quat_rotate',
    'quat_identity',
    'quat_canonical',
    'quat_angle',
    'quat_slerp',
    'quat_to_matrix',
    'matrix_to_quat',
    'axis_angle_to_quat',
    'quat_to_axis_angle',
    'axis_angle_to_matrix',
    'matrix_to_axis_angle',
    'matrix_to_rot6d',
    'rot6d_to_matrix',
    'quat_to_rot6d',
    'rot6d_to_quat',
    'euler_to_matrix',
    'matrix_to_euler',
    'euler_to_quat',
    'quat_to_euler',
    'skew',
    'quat_from_two_vectors',
    'closest_yaw',
]

_NP = array_namespace(np.empty(0))


# --------------------------------------------------------------------------
# internal helpers
# --------------------------------------------------------------------------
def _prep(*xs: Any) -> Tuple[Any, list]:
    """Return ``(xp, arrays)``: the common namespace and floating-point arrays.

    Non-array arguments (Python scalars, lists, NumPy scalars) are converted to
    the namespace / dtype / device of the first real array argument (NumPy
    float64 when there is none); integer arrays are promoted to float64.
    """
    if all(type(x) is np.ndarray and x.dtype == np.float64 for x in xs):
        return _NP, list(xs)                  # the common case, without the generic checks
    ref = None
    for x in xs:
        if is_array_api_obj(x) and not isinstance(x, np.generic):
            ref = x
            break
    if ref is None:
        xp = _NP
        return xp, [xp.asarray(x, dtype=xp.float64) for x in xs]
    xp = array_namespace(*[x for x in xs if is_array_api_obj(x) and not isinstance(x, np.generic)])
    dtype = ref.dtype if xp.isdtype(ref.dtype, 'real floating') else xp.float64
    dev = _device(ref)
    out = []
    for x in xs:
        if not is_array_api_obj(x) or isinstance(x, np.generic):
            x = xp.asarray(x, dtype=dtype, device=dev)
        elif not xp.isdtype(x.dtype, 'real floating'):
            x = xp.astype(x, xp.float64)
        out.append(x)
    return xp, out


def _check_last(x: Array, n: int, name: str) -> None:
    if x.ndim < 1 or x.shape[-1] != n:
        raise ValueError(f'{name} must have shape (..., {n}), got {tuple(x.shape)}')


def _check_mat(x: Array, name: str = 'R') -> None:
    if x.ndim < 2 or tuple(x.shape[-2:]) != (3, 3):
        raise ValueError(f'{name} must have shape (..., 3, 3), got {tuple(x.shape)}')


def _dot(xp: Any, a: Array, b: Array) -> Array:
    """Dot product over the last axis, keeping it: ``(..., 1)``."""
    return xp.sum(a * b, axis=-1, keepdims=True)


def _cross(xp: Any, a: Array, b: Array) -> Array:
    """Broadcasting cross product of 3-vectors over the last axis."""
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return xp.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=-1)


def _safe_sqrt(xp: Any, x2: Array) -> Array:
    """``sqrt(x2)`` for ``x2 >= 0`` whose gradient at 0 is 0 instead of inf/NaN."""
    pos = x2 > 0
    root = xp.sqrt(xp.where(pos, x2, xp.ones_like(x2)))
    return xp.where(pos, root, xp.zeros_like(x2))


def _safe_norm(xp: Any, v: Array, keepdims: bool = False) -> Array:
    """Euclidean norm over the last axis with a zero (finite) gradient at 0."""
    return _safe_sqrt(xp, xp.sum(v * v, axis=-1, keepdims=keepdims))


def _safe_atan2(xp: Any, y: Array, x: Array, invalid: Array) -> Array:
    """``atan2(y, x)`` evaluated at (0, 1) where ``invalid`` (keeps gradients finite)."""
    y = xp.where(invalid, xp.zeros_like(y), y)
    x = xp.where(invalid, xp.ones_like(x), x)
    return xp.atan2(y, x)


def _eps(xp: Any, x: Array) -> float:
    return float(xp.finfo(x.dtype).eps)


# --------------------------------------------------------------------------
# quaternion algebra
# --------------------------------------------------------------------------
def quat_normalize(q: Array) -> Array:
    """Unit quaternion ``q / |q|``.  ``(..., 4) -> (..., 4)``."""
    xp, (q,) = _prep(q)
    _check_last(q, 4, 'q')
    return q / xp.linalg.vector_norm(q, axis=-1, keepdims=True)


def quat_conjugate(q: Array) -> Array:
    """Conjugate ``(-x, -y, -z, w)``.  ``(..., 4) -> (..., 4)``."""
    xp, (q,) = _prep(q)
    _check_last(q, 4, 'q')
    return xp.concat([-q[..., :3], q[..., 3:]], axis=-1)


def quat_inverse(q: Array) -> Array:
    """Multiplicative inverse ``conj(q) / |q|^2`` (== conjugate for unit q).  ``(..., 4)``."""
    xp, (q,) = _prep(q)
    _check_last(q, 4, 'q')
    return quat_conjugate(q) / _dot(xp, q, q)


def quat_multiply(a: Array, b: Array) -> Array:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``).

    ``a``: ``(..., 4)``, ``b``: ``(..., 4)``; leading dims broadcast.
    """
    xp, (a, b) = _prep(a, b)
    _check_last(a, 4, 'a')
    _check_last(b, 4, 'b')
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return xp.stack([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ], axis=-1)


def quat_rotate(q: Array, v: Array) -> Array:
    """Rotate 3-vectors: ``R(q) @ v``.  ``q``: ``(..., 4)``, ``v``: ``(..., 3)`` -> ``(..., 3)``.

    ``q`` need not be normalized.  Leading dims broadcast.
    """
    xp, (q, v) = _prep(q, v)
    _check_last(q, 4, 'q')
    _check_last(v, 3, 'v')
    u = q[..., :3]
    w = q[..., 3:]
    s = 2.0 / _dot(xp, q, q)
    t = _cross(xp, u, v)
    return v + s * (w * t + _cross(xp, u, t))


def quat_identity(shape: Union[int, Sequence[int]] = (), like: Array = None) -> Array:
    """Identity quaternions ``(0, 0, 0, 1)`` of shape ``(*shape, 4)``.

    ``like``: optional array whose namespace, floating dtype and device are
    used; default NumPy float64.
    """
    if isinstance(shape, int):
        shape = (shape,)
    shape = tuple(int(s) for s in shape)
    if like is None:
        xp, dtype, dev = _NP, _NP.float64, None
    else:
        xp, (like,) = _prep(like)
        dtype, dev = like.dtype, _device(like)
    zeros = xp.zeros(shape + (3,), dtype=dtype, device=dev)
    ones = xp.ones(shape + (1,), dtype=dtype, device=dev)
    return xp.concat([zeros, ones], axis=-1)


def quat_canonical(q: Array) -> Array:
    """Representative in the ``w >= 0`` hemisphere (``q`` and ``-q`` are the same rotation)."""
    xp, (q,) = _prep(q)
    _check_last(q, 4, 'q')
    return xp.where(q[..., 3:] < 0, -q, q)


def quat_angle(a: Array, b: Array) -> Array:
    """Geodesic angle in ``[0, pi]`` between rotations ``a`` and ``b``.  ``(..., 4) -> (...)``.

    Computed as ``2 * atan2(|r_xyz|, |r_w|)`` of ``r = conj(a) * b``, which is
    accurate near 0 and pi (unlike ``acos``) and scale-invariant.
    """
    xp, (a, b) = _prep(a, b)
    r = quat_multiply(quat_conjugate(a), b)
    return 2.0 * xp.atan2(_safe_norm(xp, r[..., :3]), xp.abs(r[..., 3]))


def quat_slerp(a: Array, b: Array, t: Array) -> Array:
    """Spherical linear interpolation along the shortest path.

    ``a``, ``b``: ``(..., 4)``; ``t``: scalar or array broadcastable with the
    leading dims (``t = 0`` gives ``a``, ``t = 1`` gives ``b`` up to sign).
    Nearly parallel inputs fall back to normalized lerp.  Returns unit
    quaternions ``(..., 4)``.
    """
    xp, (a, b, t) = _prep(a, b, t)
    _check_last(a, 4, 'a')
    _check_last(b, 4, 'b')
    a = quat_normalize(a)
    b = quat_normalize(b)
    b = xp.where(_dot(xp, a, b) < 0, -b, b)
    t = t[..., None]
    # angle between the two unit 4-vectors, stable for small and large angles
    theta = 2.0 * xp.atan2(_safe_norm(xp, a - b, keepdims=True),
                           _safe_norm(xp, a + b, keepdims=True))
    small = theta < 1e-6
    theta_s = xp.where(small, xp.ones_like(theta), theta)
    sin_theta = xp.sin(theta_s)
    wa = xp.where(small, 1.0 - t, xp.sin((1.0 - t) * theta_s) / sin_theta)
    wb = xp.where(small, t, xp.sin(t * theta_s) / sin_theta)
    return quat_normalize(wa * a + wb * b)


# --------------------------------------------------------------------------
# quaternion <-> matrix
# --------------------------------------------------------------------------
def quat_to_matrix(q: Array) -> Array:
    """Rotation matrix of a (not necessarily unit) quaternion.  ``(..., 4) -> (..., 3, 3)``."""
    if type(q) is np.ndarray and q.dtype == np.float64 and q.ndim >= 1 and q.shape[-1] == 4:
        return _quat_to_matrix_np(q)          # the common case, without the generic stacks
    xp, (q,) = _prep(q)
    _check_last(q, 4, 'q')
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    s = 2.0 / (x * x + y * y + z * z + w * w)
    xx, yy, zz = s * x * x, s * y * y, s * z * z
    xy, xz, yz = s * x * y, s * x * z, s * y * z
    wx, wy, wz = s * w * x, s * w * y, s * w * z
    return xp.stack([
        xp.stack([1.0 - (yy + zz), xy - wz, xz + wy], axis=-1),
        xp.stack([xy + wz, 1.0 - (xx + zz), yz - wx], axis=-1),
        xp.stack([xz - wy, yz + wx, 1.0 - (xx + yy)], axis=-1),
    ], axis=-2)


def _quat_to_matrix_np(q: np.ndarray) -> np.ndarray:
    """:func:`quat_to_matrix` for a float64 NumPy array, written into one output array."""
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    s = 2.0 / (x * x + y * y + z * z + w * w)
    xx, yy, zz = s * x * x, s * y * y, s * z * z      # the generic path's order of operations
    xy, xz, yz = s * x * y, s * x * z, s * y * z
    wx, wy, wz = s * w * x, s * w * y, s * w * z
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1.0 - (yy + zz)
    R[..., 0, 1] = xy - wz
    R[..., 0, 2] = xz + wy
    R[..., 1, 0] = xy + wz
    R[..., 1, 1] = 1.0 - (xx + zz)
    R[..., 1, 2] = yz - wx
    R[..., 2, 0] = xz - wy
    R[..., 2, 1] = yz + wx
    R[..., 2, 2] = 1.0 - (xx + yy)
    return R


def matrix_to_quat(R: Array) -> Array:
    """Unit quaternion (canonical, ``w >= 0``) of a rotation matrix.  ``(..., 3, 3) -> (..., 4)``.

    Shepperd's method: the four candidates ``4 q_i q`` are formed from the
    matrix entries and, per element, the one with the largest denominator
    ``4 q_i^2`` is selected with a mask (no data-dependent Python branching),
    so every angle including 180 deg is handled accurately.
    """
    if type(R) is np.ndarray and R.dtype == np.float64 and R.shape[-2:] == (3, 3):
        return _matrix_to_quat_np(R)          # the common case, without the generic stacks
    xp, (R,) = _prep(R)
    _check_mat(R)
    m00, m01, m02 = R[..., 0, 0], R[..., 0, 1], R[..., 0, 2]
    m10, m11, m12 = R[..., 1, 0], R[..., 1, 1], R[..., 1, 2]
    m20, m21, m22 = R[..., 2, 0], R[..., 2, 1], R[..., 2, 2]
    d0 = 1.0 + m00 - m11 - m22  # 4 x^2
    d1 = 1.0 - m00 + m11 - m22  # 4 y^2
    d2 = 1.0 - m00 - m11 + m22  # 4 z^2
    d3 = 1.0 + m00 + m11 + m22  # 4 w^2
    cands = xp.stack([
        xp.stack([d0, m01 + m10, m02 + m20, m21 - m12], axis=-1),  # 4x * q
        xp.stack([m01 + m10, d1, m12 + m21, m02 - m20], axis=-1),  # 4y * q
        xp.stack([m02 + m20, m12 + m21, d2, m10 - m01], axis=-1),  # 4z * q
        xp.stack([m21 - m12, m02 - m20, m10 - m01, d3], axis=-1),  # 4w * q
    ], axis=-2)
    best = xp.argmax(xp.stack([d0, d1, d2, d3], axis=-1), axis=-1)
    mask = best[..., None] == xp.arange(4, dtype=best.dtype, device=_device(R))
    q = xp.sum(xp.where(mask[..., None], cands, xp.zeros_like(cands)), axis=-2)
    q = q / xp.linalg.vector_norm(q, axis=-1, keepdims=True)
    return xp.where(q[..., 3:] < 0, -q, q)


def _matrix_to_quat_np(R: np.ndarray) -> np.ndarray:
    """:func:`matrix_to_quat` for a float64 NumPy array: the same candidates and choice, the
    chosen candidate taken by index instead of a masked sum."""
    m00, m01, m02 = R[..., 0, 0], R[..., 0, 1], R[..., 0, 2]
    m10, m11, m12 = R[..., 1, 0], R[..., 1, 1], R[..., 1, 2]
    m20, m21, m22 = R[..., 2, 0], R[..., 2, 1], R[..., 2, 2]
    c = np.empty(R.shape[:-2] + (4, 4))
    c[..., 0, 0] = 1.0 + m00 - m11 - m22      # 4 x^2
    c[..., 1, 1] = 1.0 - m00 + m11 - m22      # 4 y^2
    c[..., 2, 2] = 1.0 - m00 - m11 + m22      # 4 z^2
    c[..., 3, 3] = 1.0 + m00 + m11 + m22      # 4 w^2
    c[..., 0, 1] = c[..., 1, 0] = m01 + m10
    c[..., 0, 2] = c[..., 2, 0] = m02 + m20
    c[..., 1, 2] = c[..., 2, 1] = m12 + m21
    c[..., 0, 3] = c[..., 3, 0] = m21 - m12
    c[..., 1, 3] = c[..., 3, 1] = m02 - m20
    c[..., 2, 3] = c[..., 3, 2] = m10 - m01
    best = np.argmax(np.diagonal(c, axis1=-2, axis2=-1), axis=-1)
    q = np.take_along_axis(c, best[..., None, None], axis=-2)[..., 0, :]
    q = q / np.sqrt(np.sum(q * q, axis=-1, keepdims=True))
    return np.where(q[..., 3:] < 0, -q, q)


# --------------------------------------------------------------------------
# axis-angle (rotation vectors)
# --------------------------------------------------------------------------
def axis_angle_to_quat(v: Array) -> Array:
    """Quaternion of a rotation vector ``axis * angle``.  ``(..., 3) -> (..., 4)``.

    Uses ``sin(theta/2)/theta`` with a Taylor expansion for tiny angles, so the
    result and its gradient are exact and finite at ``v = 0``.
    """
    if type(v) is np.ndarray and v.dtype == np.float64 and v.ndim >= 1 and v.shape[-1] == 3:
        xp = _NP                              # the common case, without the generic checks
    else:
        xp, (v,) = _prep(v)
        _check_last(v, 3, 'v')
    th2 = _dot(xp, v, v)
    small = th2 < 1e-6
    th = xp.sqrt(xp.where(small, xp.ones_like(th2), th2))
    k = xp.where(small, 0.5 - th2 / 48.0 + th2 * th2 / 3840.0, xp.sin(0.5 * th) / th)
    w = xp.where(small, 1.0 - th2 / 8.0 + th2 * th2 / 384.0, xp.cos(0.5 * th))
    return xp.concat([k * v, w], axis=-1)


def quat_to_axis_angle(q: Array) -> Array:
    """Rotation vector (angle in ``[0, pi]``) of a quaternion.  ``(..., 4) -> (..., 3)``.

    ``angle = 2 atan2(|xyz|, w)`` on the canonical (``w >= 0``) quaternion;
    a Taylor expansion of ``atan(r)/r`` keeps it exact and smooth near 0.
    """
    xp, (q,) = _prep(q)
    _check_last(q, 4, 'q')
    q = quat_canonical(q)
    u = q[..., :3]
    w = q[..., 3:]
    n2 = _dot(xp, u, u)
    small = n2 < 1e-6 * (w * w)  # |xyz| / w < 1e-3
    n = xp.sqrt(xp.where(small, xp.ones_like(n2), n2))
    w_s = xp.where(small, w, xp.ones_like(w))
    r2 = n2 / (w_s * w_s)
    scale = xp.where(small,
                     (2.0 / w_s) * (1.0 - r2 / 3.0 + r2 * r2 / 5.0),
                     2.0 * xp.atan2(n, w) / n)
    return u * scale


def axis_angle_to_matrix(v: Array) -> Array:
    """Rotation matrix of a rotation vector.  ``(..., 3) -> (..., 3, 3)``."""
    return quat_to_matrix(axis_angle_to_quat(v))


def matrix_to_axis_angle(R: Array) -> Array:
    """Rotation vector (angle in ``[0, pi]``) of a rotation matrix: ``(..., 3, 3) -> (..., 3)``."""
    return quat_to_axis_angle(matrix_to_quat(R))


# --------------------------------------------------------------------------
# 6D representation
# --------------------------------------------------------------------------
def matrix_to_rot6d(R: Array) -> Array:
    """First two columns of ``R`` concatenated, ``[R[:, 0], R[:, 1]]``.

    ``(..., 3, 3) -> (..., 6)``.
    """
    xp, (R,) = _prep(R)
    _check_mat(R)
    return xp.concat([R[..., :, 0], R[..., :, 1]], axis=-1)


def rot6d_to_matrix(d: Array) -> Array:
    """Rotation matrix from the 6D representation by Gram--Schmidt.  ``(..., 6) -> (..., 3, 3)``.

    Column 0 = normalized ``d[:3]``; column 1 = ``d[3:]`` orthogonalized against
    column 0 and normalized; column 2 = column 0 x column 1.
    """
    xp, (d,) = _prep(d)
    _check_last(d, 6, 'd')
    a1 = d[..., :3]
    a2 = d[..., 3:]
    b1 = a1 / xp.linalg.vector_norm(a1, axis=-1, keepdims=True)
    b2 = a2 - _dot(xp, b1, a2) * b1
    b2 = b2 / xp.linalg.vector_norm(b2, axis=-1, keepdims=True)
    b3 = _cross(xp, b1, b2)
    return xp.stack([b1, b2, b3], axis=-1)


def quat_to_rot6d(q: Array) -> Array:
    """6D representation of a quaternion.  ``(..., 4) -> (..., 6)``."""
    return matrix_to_rot6d(quat_to_matrix(q))


def rot6d_to_quat(d: Array) -> Array:
    """Canonical quaternion of a 6D representation.  ``(..., 6) -> (..., 4)``."""
    return matrix_to_quat(rot6d_to_matrix(d))


# --------------------------------------------------------------------------
# Euler angles
# --------------------------------------------------------------------------
_AXES = {'x': 0, 'y': 1, 'z': 2}
_CYCLIC = ((0, 1, 2), (1, 2, 0), (2, 0, 1))


def _parse_order(order: str) -> Tuple[Tuple[int, int, int], bool]:
    """``(axes, intrinsic)`` for a SciPy-style sequence such as ``'ZYX'`` or ``'xzx'``."""
    if not isinstance(order, str) or len(order) != 3:
        raise ValueError(
            f"Euler order must be a 3-letter string like 'XYZ' or 'zxz', got {order!r}")
    if order.isupper():
        intrinsic = True
    elif order.islower():
        intrinsic = False
    else:
        raise ValueError(
            f'Euler order {order!r} mixes intrinsic (upper) and extrinsic (lower) axes')
    try:
        axes = tuple(_AXES[c] for c in order.lower())
    except KeyError:
        raise ValueError(f'Euler order {order!r} may only contain the axes x, y, z') from None
    if axes[0] == axes[1] or axes[1] == axes[2]:
        raise ValueError(f'Euler order {order!r}: consecutive axes must differ')
    return axes, intrinsic  # type: ignore[return-value]


def _elemental_matrix(xp: Any, axis: int, angle: Array) -> Array:
    c, s = xp.cos(angle), xp.sin(angle)
    one, zero = xp.ones_like(angle), xp.zeros_like(angle)
    if axis == 0:
        rows = [[one, zero, zero], [zero, c, -s], [zero, s, c]]
    elif axis == 1:
        rows = [[c, zero, s], [zero, one, zero], [-s, zero, c]]
    else:
        rows = [[c, -s, zero], [s, c, zero], [zero, zero, one]]
    return xp.stack([xp.stack(r, axis=-1) for r in rows], axis=-2)


def _elemental_quat(xp: Any, axis: int, angle: Array) -> Array:
    half = 0.5 * angle
    s, zero = xp.sin(half), xp.zeros_like(angle)
    comps = [zero, zero, zero, xp.cos(half)]
    comps[axis] = s
    return xp.stack(comps, axis=-1)


def _sequence(angles: Array, order: str) -> Tuple[Any, list]:
    """``(xp, [(axis, angle), ...])`` in left-to-right matrix product order."""
    xp, (angles,) = _prep(angles)
    _check_last(angles, 3, 'angles')
    axes, intrinsic = _parse_order(order)
    seq = [(axes[n], angles[..., n]) for n in range(3)]
    if not intrinsic:
        seq = seq[::-1]
    return xp, seq


def euler_to_matrix(angles: Array, order: str) -> Array:
    """Rotation matrix from Euler angles.  ``(..., 3) -> (..., 3, 3)``.

    ``order`` as in SciPy: ``'XYZ'`` (intrinsic) gives ``Rx(a) @ Ry(b) @ Rz(c)``,
    ``'xyz'`` (extrinsic) gives ``Rz(c) @ Ry(b) @ Rx(a)``.
    """
    xp, seq = _sequence(angles, order)
    (i, a), (j, b), (k, c) = seq
    return _elemental_matrix(xp, i, a) @ _elemental_matrix(xp, j, b) @ _elemental_matrix(xp, k, c)


def euler_to_quat(angles: Array, order: str) -> Array:
    """Quaternion from Euler angles (product of elemental quaternions, not canonicalized).

    ``(..., 3) -> (..., 4)``; ``order`` as in :func:`euler_to_matrix`.
    """
    xp, seq = _sequence(angles, order)
    (i, a), (j, b), (k, c) = seq
    q = quat_multiply(_elemental_quat(xp, i, a), _elemental_quat(xp, j, b))
    return quat_multiply(q, _elemental_quat(xp, k, c))


def matrix_to_euler(R: Array, order: str) -> Array:
    """Euler angles of a rotation matrix.  ``(..., 3, 3) -> (..., 3)``.

    Ranges: Tait--Bryan middle angle in ``[-pi/2, pi/2]``, proper Euler middle
    angle in ``[0, pi]``, the others in ``[-pi, pi]``.  In gimbal lock (cos or
    sin of the middle angle below ``sqrt(eps)`` of the dtype) the last angle
    ``angles[..., 2]`` is set to 0 and the first one absorbs the whole rotation
    about the locked axis, matching SciPy's ``as_euler``.
    """
    xp, (R,) = _prep(R)
    _check_mat(R)
    axes, intrinsic = _parse_order(order)
    if not intrinsic:  # extrinsic = intrinsic on the reversed order, angles reversed
        axes = axes[::-1]
    i, j, k = axes
    proper = i == k
    if proper:
        k = 3 - i - j
    s = 1.0 if (i, j, k) in _CYCLIC else -1.0
    tol = float(np.sqrt(_eps(xp, R)))

    def m(r: int, c: int) -> Array:
        return R[..., r, c]

    if proper:
        # R = R_i(a) R_j(b) R_i(c): R[i,i] = cos b, R[i,j] = sin b sin c, R[i,k] = s sin b cos c,
        # R[j,i] = sin a sin b, R[k,i] = -s cos a sin b
        cos_b = m(i, i)
        sin_b = _safe_sqrt(xp, m(i, j) * m(i, j) + m(i, k) * m(i, k))
        lock = sin_b < tol
        b = xp.atan2(sin_b, cos_b)
        a = _safe_atan2(xp, m(j, i), -s * m(k, i), lock)
        c = _safe_atan2(xp, m(i, j), s * m(i, k), lock)
    else:
        # R = R_i(a) R_j(b) R_k(c): R[i,k] = s sin b, R[i,i] = cos b cos c,
        # R[i,j] = -s cos b sin c, R[k,k] = cos a cos b, R[j,k] = -s sin a cos b
        sin_b = s * m(i, k)
        cos_b = _safe_sqrt(xp, m(i, i) * m(i, i) + m(i, j) * m(i, j))
        lock = cos_b < tol
        b = xp.atan2(sin_b, cos_b)
        a = _safe_atan2(xp, -s * m(j, k), m(k, k), lock)
        c = _safe_atan2(xp, -s * m(i, j), m(i, i), lock)
    # Gimbal lock: only a + c (or a - c) is determined.  Like SciPy, the angle that comes
    # last in the user's sequence is set to 0: c for intrinsic, a for extrinsic orders.
    if intrinsic:
        # c := 0: R = R_i(a) R_j(b), so R[:, j] = R_i(a) e_j = cos a e_j + s sin a e_k
        a = xp.where(lock, _safe_atan2(xp, s * m(k, j), m(j, j), ~lock), a)
        c = xp.where(lock, xp.zeros_like(c), c)
        return xp.stack([a, b, c], axis=-1)
    # a := 0: R = R_j(b) R_t(c) with t the third axis, so R[j, :] = e_j^T R_t(c):
    # Tait-Bryan (t = k): R[j, i] = s sin c; proper (t = i): R[j, k] = -s sin c
    if proper:
        c_lock = _safe_atan2(xp, -s * m(j, k), m(j, j), ~lock)
    else:
        c_lock = _safe_atan2(xp, s * m(j, i), m(j, j), ~lock)
    a = xp.where(lock, xp.zeros_like(a), a)
    c = xp.where(lock, c_lock, c)
    return xp.stack([c, b, a], axis=-1)


def quat_to_euler(q: Array, order: str) -> Array:
    """Euler angles of a quaternion.  ``(..., 4) -> (..., 3)``; see :func:`matrix_to_euler`."""
    return matrix_to_euler(quat_to_matrix(q), order)


# --------------------------------------------------------------------------
# misc
# --------------------------------------------------------------------------
def skew(v: Array) -> Array:
    """Cross-product matrix: ``skew(v) @ u == cross(v, u)``.  ``(..., 3) -> (..., 3, 3)``."""
    xp, (v,) = _prep(v)
    _check_last(v, 3, 'v')
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    zero = xp.zeros_like(x)
    return xp.stack([
        xp.stack([zero, -z, y], axis=-1),
        xp.stack([z, zero, -x], axis=-1),
        xp.stack([-y, x, zero], axis=-1),
    ], axis=-2)


def quat_from_two_vectors(a: Array, b: Array) -> Array:
    """Unit quaternion of the minimal rotation taking direction ``a`` to direction ``b``.

    ``a``, ``b``: ``(..., 3)`` (any non-zero length) -> ``(..., 4)``.  For
    (nearly) antiparallel inputs the result is a 180 deg rotation about an axis
    perpendicular to ``a`` (built from the coordinate axis least aligned with ``a``).
    """
    xp, (a, b) = _prep(a, b)
    _check_last(a, 3, 'a')
    _check_last(b, 3, 'b')
    a = a / xp.linalg.vector_norm(a, axis=-1, keepdims=True)
    b = b / xp.linalg.vector_norm(b, axis=-1, keepdims=True)
    a, b = xp.broadcast_arrays(a, b)
    w = 1.0 + _dot(xp, a, b)  # = 2 cos^2(theta/2)
    v = _cross(xp, a, b)
    least = xp.argmin(xp.abs(a), axis=-1)
    e = xp.astype(least[..., None] == xp.arange(3, dtype=least.dtype, device=_device(a)), a.dtype)
    perp = _cross(xp, a, e)
    perp = perp / xp.linalg.vector_norm(perp, axis=-1, keepdims=True)
    anti = w < 16.0 * _eps(xp, w)
    q = xp.where(anti, xp.concat([perp, xp.zeros_like(w)], axis=-1), xp.concat([v, w], axis=-1))
    return quat_normalize(q)


def closest_yaw(R: np.ndarray) -> float:
    """The angle (rad) of the rotation about z nearest to the (3, 3) rotation ``R`` (in the
    Frobenius norm: the turn about z that a tilted rotation stands for), ``atan2(R10 - R01,
    R00 + R11)``. NumPy only."""
    R = np.asarray(R, dtype=float)
    return float(np.arctan2(R[1, 0] - R[0, 1], R[0, 0] + R[1, 1]))
