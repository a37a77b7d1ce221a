"""A synthetic BVH clip made in code (no ROS imports).

:func:`synthetic_walk_bvh` writes a small walking-like clip with the joint names, channel
layout (root ``Xposition Yposition Zposition Zrotation Yrotation Xrotation``, joints
``Zrotation Yrotation Xrotation``) and length unit (CMU ASF units, 0.0564 m) of the CMU
"MotionBuilder-friendly" conversion, so the whole data pipeline (parse, retarget, process,
bags) can be exercised where the real motion capture of ``../shared/data`` is absent (tests,
users without the data). It is not motion capture: legs swing sinusoidally in antiphase while
the root moves forward at a constant speed.
"""

from __future__ import annotations

import numpy as np

__all__ = ['synthetic_walk_bvh']

# (name, parent, offset in CMU ASF units: x left, y up, z forward)
_JOINTS = (
    ('Hips', None, (0.0, 0.0, 0.0)),
    ('LeftUpLeg', 'Hips', (1.6, -0.8, 0.0)),
    ('LeftLeg', 'LeftUpLeg', (0.0, -7.4, 0.0)),
    ('LeftFoot', 'LeftLeg', (0.0, -7.4, 0.0)),
    ('LeftToeBase', 'LeftFoot', (0.0, -1.0, 2.2)),
    ('RightUpLeg', 'Hips', (-1.6, -0.8, 0.0)),
    ('RightLeg', 'RightUpLeg', (0.0, -7.4, 0.0)),
    ('RightFoot', 'RightLeg', (0.0, -7.4, 0.0)),
    ('RightToeBase', 'RightFoot', (0.0, -1.0, 2.2)),
    ('Spine', 'Hips', (0.0, 3.5, 0.0)),
    ('Spine1', 'Spine', (0.0, 2.5, 0.0)),
    ('Head', 'Spine1', (0.0, 4.5, 0.0)),
    ('LeftArm', 'Spine1', (3.0, 2.5, 0.0)),
    ('LeftForeArm', 'LeftArm', (5.2, 0.0, 0.0)),
    ('LeftHand', 'LeftForeArm', (4.5, 0.0, 0.0)),
    ('LeftFingerBase', 'LeftHand', (1.0, 0.0, 0.0)),
    ('RightArm', 'Spine1', (-3.0, 2.5, 0.0)),
    ('RightForeArm', 'RightArm', (-5.2, 0.0, 0.0)),
    ('RightHand', 'RightForeArm', (-4.5, 0.0, 0.0)),
    ('RightFingerBase', 'RightHand', (-1.0, 0.0, 0.0)),
)
_END_SITES = {'LeftToeBase': (0.0, 0.0, 1.0), 'RightToeBase': (0.0, 0.0, 1.0),
              'Head': (0.0, 2.0, 0.0), 'LeftFingerBase': (1.0, 0.0, 0.0),
              'RightFingerBase': (-1.0, 0.0, 0.0)}


def synthetic_walk_bvh(frames: int = 120, fps: float = 120.0, speed_m_s: float = 1.2,
                       step_hz: float = 1.0, crlf: bool = False) -> str:
    """BVH text of a synthetic walk (module docstring): ``frames`` frames at ``fps``."""
    names = [j[0] for j in _JOINTS]
    children = {n: [j[0] for j in _JOINTS if j[1] == n] for n in names}
    offsets = {j[0]: j[2] for j in _JOINTS}
    lines = ['HIERARCHY']

    def emit(name: str, depth: int) -> None:
        pad = '  ' * depth
        kind = 'ROOT' if depth == 0 else 'JOINT'
        lines.append(f'{pad}{kind} {name}')
        lines.append(f'{pad}{{')
        o = offsets[name]
        lines.append(f'{pad}  OFFSET {o[0]:.4f} {o[1]:.4f} {o[2]:.4f}')
        if depth == 0:
            lines.append(f'{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation '
                         'Yrotation Xrotation')
        else:
            lines.append(f'{pad}  CHANNELS 3 Zrotation Yrotation Xrotation')
        for c in children[name]:
            emit(c, depth + 1)
        if name in _END_SITES:
            e = _END_SITES[name]
            lines.append(f'{pad}  End Site')
            lines.append(f'{pad}  {{')
            lines.append(f'{pad}    OFFSET {e[0]:.4f} {e[1]:.4f} {e[2]:.4f}')
            lines.append(f'{pad}  }}')
        lines.append(f'{pad}}}')

    emit('Hips', 0)
    unit = 0.0254 / 0.45
    t = np.arange(frames) / fps
    phase = 2 * np.pi * step_hz * t
    col = {n: i for i, n in enumerate(names)}
    data = np.zeros((frames, 6 + 3 * (len(names) - 1)))
    data[:, 1] = 16.2 + 0.15 * np.cos(2 * phase)           # hip height (units), small bob
    data[:, 2] = speed_m_s * t / unit                      # forward along +z
    swing = 25.0 * np.sin(phase)

    def rot(name: str, axis: str) -> int:                  # column of a rotation channel
        return 6 + 3 * (col[name] - 1) + 'ZYX'.index(axis)

    data[:, rot('LeftUpLeg', 'X')] = -swing
    data[:, rot('RightUpLeg', 'X')] = swing
    data[:, rot('LeftLeg', 'X')] = 30.0 * np.clip(np.sin(phase + 0.6), 0, None)
    data[:, rot('RightLeg', 'X')] = 30.0 * np.clip(-np.sin(phase + 0.6), 0, None)
    data[:, rot('LeftArm', 'Z')] = -70.0                   # arms down from the T-pose
    data[:, rot('RightArm', 'Z')] = 70.0
    data[:, rot('LeftArm', 'Y')] = -0.5 * swing
    data[:, rot('RightArm', 'Y')] = -0.5 * swing
    lines.append('MOTION')
    lines.append(f'Frames: {frames}')
    lines.append(f'Frame Time: {1.0 / fps:.7f}')
    lines.extend(' '.join(f'{v:.4f}' for v in row) for row in data)
    sep = '\r\n' if crlf else '\n'
    return sep.join(lines) + sep
