"""Forward kinematics for tree skeletons, shared by NumPy and PyTorch.

One implementation written against the array API (``array_api_compat``):
NumPy inputs give NumPy outputs, torch tensors give differentiable torch
tensors.  Everything is batched over arbitrary leading dimensions ``...``.

Conventions (see :mod:`mocap_core.rotations`): quaternions are ``(x, y, z, w)``,
rotation matrices act on column vectors.

Skeleton
--------
``parents`` is a sequence of ``J`` ints in topological order:
``parents[0] == -1`` (the root) and ``0 <= parents[j] < j`` for ``j >= 1``.
``offsets[j]`` is joint ``j``'s translation from its parent, expressed in the
parent's frame in the rest pose.  ``offsets[0]`` is **ignored** (the root is
placed at ``root_position``).

Forward kinematics::

    G_0 = L_0,                  p_0 = root_position
    G_j = G_parent(j) @ L_j,    p_j = p_parent(j) + G_parent(j) @ offsets[j]
"""

from __future__ import annotations

import functools
import operator
from typing import NamedTuple, Optional, Sequence, Tuple

import numpy as np
from array_api_compat import device as _device

from .rotations import Array, _prep, quat_to_matrix

__all__ = [
    'FKResult',
    'forward_kinematics',
    'local_from_global_rotations',
    'bone_lengths',
    'transform_points',
]


class FKResult(NamedTuple):
    """Result of :func:`forward_kinematics`."""

    positions: Array
    """World joint positions, ``(..., J, 3)``."""
    global_rotations: Array
    """World joint orientations (joint frame -> world), ``(..., J, 3, 3)``."""


def _validate_parents(parents: Sequence[int]) -> Tuple[int, ...]:
    """Return ``parents`` as a tuple of ints, or raise ``ValueError``."""
    try:
        p = tuple(operator.index(x) for x in parents)
    except TypeError:
        raise ValueError(f'parents must be a sequence of ints, got {parents!r}') from None
    if len(p) == 0:
        raise ValueError('parents must contain at least the root joint')
    if p[0] != -1:
        raise ValueError(f'parents[0] must be -1 (the root), got {p[0]}')
    for j in range(1, len(p)):
        if not 0 <= p[j] < j:
            raise ValueError(
                f'parents must be in topological order with 0 <= parents[j] < j; '
                f'got parents[{j}] = {p[j]}')
    return p


def _check_joints(x: Array, trailing: Tuple[int, ...], name: str) -> None:
    n = len(trailing)
    if x.ndim < n or tuple(x.shape[-n:]) != trailing:
        raise ValueError(f'{name} must have shape (..., {", ".join(map(str, trailing))}), '
                         f'got {tuple(x.shape)}')


def forward_kinematics(parents: Sequence[int], offsets: Array, local_rotations: Array,
                       root_position: Array, *, rotation_format: str = 'quat') -> FKResult:
    """World joint positions and orientations of a posed skeleton.

    Args:
        parents: ``J`` parent indices (``parents[0] == -1``, ``parents[j] < j``).
        offsets: ``(..., J, 3)`` or unbatched ``(J, 3)`` rest-pose offsets of each
            joint from its parent in the parent's frame; ``offsets[..., 0, :]``
            is ignored.
        local_rotations: ``(..., J, 4)`` quaternions ``(x, y, z, w)``
            (``rotation_format='quat'``) or ``(..., J, 3, 3)`` matrices
            (``rotation_format='matrix'``): rotation of joint ``j`` relative to
            its parent; entry 0 is the root's global orientation.
        root_position: ``(..., 3)`` world position of joint 0.
        rotation_format: ``'quat'`` or ``'matrix'``.

    Leading dims of the three arrays broadcast together.

    Returns:
        :class:`FKResult` with ``positions (..., J, 3)`` and
        ``global_rotations (..., J, 3, 3)``.
    """
    p = _validate_parents(parents)
    J = len(p)
    if rotation_format not in ('quat', 'matrix'):
        raise ValueError(f"rotation_format must be 'quat' or 'matrix', got {rotation_format!r}")
    fast = _fk_single_np(p, offsets, local_rotations, root_position, rotation_format)
    if fast is not None:
        return fast
    xp, (offsets, local_rotations, root) = _prep(offsets, local_rotations, root_position)
    _check_joints(offsets, (J, 3), 'offsets')
    _check_joints(root, (3,), 'root_position')
    if rotation_format == 'quat':
        _check_joints(local_rotations, (J, 4), 'local_rotations')
        L = quat_to_matrix(local_rotations)
    else:
        _check_joints(local_rotations, (J, 3, 3), 'local_rotations')
        L = local_rotations
    batch = tuple(np.broadcast_shapes(tuple(offsets.shape[:-2]), tuple(L.shape[:-3]),
                                      tuple(root.shape[:-1])))
    G = [xp.broadcast_to(L[..., 0, :, :], batch + (3, 3))]
    P = [xp.broadcast_to(root, batch + (3,))]
    for j in range(1, J):
        Gp = G[p[j]]
        G.append(Gp @ L[..., j, :, :])
        P.append(P[p[j]] + (Gp @ offsets[..., j, :, None])[..., 0])
    return FKResult(positions=xp.stack(P, axis=-2), global_rotations=xp.stack(G, axis=-3))


def _fk_single_np(p: Sequence[int], offsets: Array, local_rotations: Array, root: Array,
                  rotation_format: str) -> Optional[FKResult]:
    """:func:`forward_kinematics` of one pose given as float64 NumPy arrays (the common case:
    the nodes' per-frame poses), written into two output arrays; None for any other input."""
    J = len(p)
    rot_shape = (J, 4) if rotation_format == 'quat' else (J, 3, 3)
    if not (type(offsets) is np.ndarray and type(local_rotations) is np.ndarray
            and type(root) is np.ndarray and offsets.dtype == np.float64
            and local_rotations.dtype == np.float64 and root.dtype == np.float64
            and offsets.shape == (J, 3) and local_rotations.shape == rot_shape
            and root.shape == (3,)):
        return None
    L = quat_to_matrix(local_rotations) if rotation_format == 'quat' else local_rotations
    G = np.empty((J, 3, 3))
    P = np.empty((J, 3))
    G[0] = L[0]
    P[0] = root
    for joints, parent in _depth_levels(tuple(p)):      # every joint of one depth at once
        Gp = G[parent]
        G[joints] = Gp @ L[joints]
        P[joints] = P[parent] + (Gp @ offsets[joints, :, None])[..., 0]
    return FKResult(positions=P, global_rotations=G)


@functools.lru_cache(maxsize=64)
def _depth_levels(parents: Tuple[int, ...]) -> Tuple[Tuple[np.ndarray, np.ndarray], ...]:
    """The non-root joints grouped by depth in the tree, root side first: per depth
    (joint indices, their parents' indices)."""
    depth = [0] * len(parents)
    for j in range(1, len(parents)):
        depth[j] = depth[parents[j]] + 1
    levels = []
    for d in range(1, max(depth, default=0) + 1):
        joints = np.array([j for j in range(len(parents)) if depth[j] == d], dtype=np.intp)
        parent = np.array([parents[j] for j in joints], dtype=np.intp)
        joints.setflags(write=False)                  # shared by every call (cached)
        parent.setflags(write=False)
        levels.append((joints, parent))
    return tuple(levels)


def local_from_global_rotations(parents: Sequence[int], global_rotations: Array) -> Array:
    """Local rotation matrices from global ones (inverse of FK's rotation part).

    ``L_0 = G_0``, ``L_j = G_parent(j)^T @ G_j``.
    ``global_rotations``: ``(..., J, 3, 3)`` -> ``(..., J, 3, 3)``.
    """
    p = _validate_parents(parents)
    xp, (G,) = _prep(global_rotations)
    _check_joints(G, (len(p), 3, 3), 'global_rotations')
    root = G[..., :1, :, :]
    if len(p) == 1:
        return xp.concat([root], axis=-3)
    idx = xp.asarray(p[1:], device=_device(G))
    Gp = xp.take(G, idx, axis=G.ndim - 3)
    rest = xp.matrix_transpose(Gp) @ G[..., 1:, :, :]
    return xp.concat([root, rest], axis=-3)


def bone_lengths(parents: Sequence[int], offsets: Array) -> Array:
    """Length of each joint's offset from its parent, 0 for the root.

    ``offsets``: ``(..., J, 3)`` -> ``(..., J)``.
    """
    p = _validate_parents(parents)
    xp, (offsets,) = _prep(offsets)
    _check_joints(offsets, (len(p), 3), 'offsets')
    n = xp.linalg.vector_norm(offsets[..., 1:, :], axis=-1)
    zero = xp.zeros(tuple(offsets.shape[:-2]) + (1,), dtype=n.dtype, device=_device(n))
    return xp.concat([zero, n], axis=-1)


def transform_points(global_rotations_j: Array, positions_j: Array, local_points: Array) -> Array:
    """Map points given in a joint's frame to world: ``R @ x + p``.

    Args:
        global_rotations_j: ``(..., 3, 3)`` world orientation of the joint.
        positions_j: ``(..., 3)`` world position of the joint.
        local_points: ``(..., P, 3)`` or ``(P, 3)`` points in the joint's frame
            (e.g. heel / toe contact points of a foot joint).

    Returns:
        ``(..., P, 3)`` world points (leading dims broadcast).
    """
    xp, (R, t, pts) = _prep(global_rotations_j, positions_j, local_points)
    _check_joints(R, (3, 3), 'global_rotations_j')
    _check_joints(t, (3,), 'positions_j')
    _check_joints(pts, (3,), 'local_points')
    if pts.ndim < 2:
        raise ValueError(f'local_points must have shape (..., P, 3), got {tuple(pts.shape)}')
    return pts @ xp.matrix_transpose(R) + t[..., None, :]
