"""Writing motion of the pipeline skeleton as BVH, the format animation tools open (no ROS).

The hierarchy is the pipeline skeleton (root ``pelvis`` with position and rotation channels,
every other joint with three rotation channels ``Zrotation Yrotation Xrotation``, applied in
that order as intrinsic rotations, degrees), offsets in centimetres, y up. End sites extend
the leaf joints (head, wrists, toes) along their bones.

Frames: the motion is given in the pipeline world frame (z up) or a camera optical frame
(x right, y down, z forward) and rotated into BVH's y-up frame: world ->
``BVH_TO_WORLD.T`` (the inverse of the reader's axis map), camera -> a half turn about x.
The rest pose (the skeleton's body frame, z up, facing +x) maps like the world, so the BVH
T-pose stands upright along +y and faces +z whatever the motion's frame.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from ..rotations import matrix_to_euler, quat_to_matrix
from ..skeleton import Skeleton
from .bvh import BVH_TO_WORLD

#: (3, 3) maps a vector in each supported frame to BVH's y-up frame.
FRAME_TO_BVH = {
    'world': np.asarray(BVH_TO_WORLD).T,
    'camera': np.diag([1.0, -1.0, -1.0]),
}
_END_SITE_FRACTION = 0.5


def write_bvh(path: str | Path, skeleton: Skeleton, rotations: np.ndarray,
              root_positions: np.ndarray, fps: float, frame: str = 'world') -> Path:
    """Write a motion as BVH.

    Args:
        skeleton: bone offsets (metres).
        rotations: (F, J, 4) local quaternions x, y, z, w (row 0: root orientation in
            ``frame``).
        root_positions: (F, 3) metres in ``frame``.
        fps: frame rate.
        frame: 'world' (z up) or 'camera' (optical frame).
    """
    if frame not in FRAME_TO_BVH:
        raise ValueError(f"frame must be one of {sorted(FRAME_TO_BVH)}, got {frame!r}")
    rot = np.asarray(rotations, dtype=np.float64)
    root = np.asarray(root_positions, dtype=np.float64)
    if rot.ndim != 3 or rot.shape[1:] != (skeleton.num_joints, 4) or len(root) != len(rot):
        raise ValueError(f'rotations (F, {skeleton.num_joints}, 4) and root (F, 3) expected, '
                         f'got {rot.shape} and {root.shape}')
    c = FRAME_TO_BVH[frame]          # the motion's frame -> BVH axes
    body = FRAME_TO_BVH['world']     # the skeleton's body frame (z up) -> BVH axes, so the
    mats = quat_to_matrix(rot)       # BVH rest pose stands upright (y up, facing +z)
    mats[:, 1:] = body @ mats[:, 1:] @ body.T
    mats[:, 0] = c @ mats[:, 0] @ body.T
    eul = np.degrees(matrix_to_euler(mats, 'ZYX'))   # (F, J, 3): Z, Y, X angles
    offsets = 100.0 * skeleton.offsets @ body.T
    children = {j: [k for k in range(skeleton.num_joints) if skeleton.parents[k] == j]
                for j in range(skeleton.num_joints)}
    lines = ['HIERARCHY']

    def emit(j: int, depth: int) -> None:
        pad = '  ' * depth
        name = skeleton.joint_names[j]
        if j == 0:
            lines.append(f'ROOT {name}')
        else:
            lines.append(f'{pad}JOINT {name}')
        lines.append(pad + '{')
        o = offsets[j]
        lines.append(f'{pad}  OFFSET {o[0]:.6f} {o[1]:.6f} {o[2]:.6f}')
        if j == 0:
            lines.append(f'{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation '
                         'Yrotation Xrotation')
        else:
            lines.append(f'{pad}  CHANNELS 3 Zrotation Yrotation Xrotation')
        for k in children[j]:
            emit(k, depth + 1)
        if not children[j]:
            e = offsets[j] * _END_SITE_FRACTION
            lines.append(f'{pad}  End Site')
            lines.append(f'{pad}  {{')
            lines.append(f'{pad}    OFFSET {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}')
            lines.append(f'{pad}  }}')
        lines.append(pad + '}')

    emit(0, 0)
    order = _depth_first(children)
    pos = 100.0 * root @ c.T
    lines += ['MOTION', f'Frames: {len(rot)}', f'Frame Time: {1.0 / fps:.8f}']
    for f in range(len(rot)):
        values = list(pos[f]) + [v for j in order for v in eul[f, j]]
        lines.append(' '.join(f'{v:.6f}' for v in values))
    path = Path(path)
    path.write_text('\n'.join(lines) + '\n')
    return path


def _depth_first(children) -> Sequence[int]:
    out, stack = [], [0]
    while stack:
        j = stack.pop()
        out.append(j)
        stack.extend(reversed(children[j]))
    return out
