"""Helpers for the packages' tests (no ROS imports): damaged and crafted weight files.

A crafted file holds a :class:`CreatesFile` object: unpickled with code execution allowed
(``torch.load(weights_only=False)``), it creates its marker file, so a test can assert that
loading never ran it.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any, Dict, Union

PathLike = Union[str, Path]


class CreatesFile:
    """Pickles as the call ``open(path, 'w')``: the payload of a crafted weights file."""

    def __init__(self, path: PathLike) -> None:
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, 'w'))


def crafted_weights(path: PathLike, marker: PathLike, key: str = 'model',
                    **entries: Any) -> Path:
    """Write a ``torch.save`` dictionary whose ``key`` holds a :class:`CreatesFile` of
    ``marker`` (plus ``entries``); returns ``path``."""
    import torch

    torch.save({key: CreatesFile(marker), **entries}, str(path))
    return Path(path)


def damaged_weights(good: PathLike, directory: PathLike) -> Dict[str, Path]:
    """``{'truncated': the first half of ``good``, 'random': 4096 random bytes}``, written to
    ``directory``."""
    directory = Path(directory)
    data = Path(good).read_bytes()
    truncated = directory / 'truncated.pt'
    truncated.write_bytes(data[:len(data) // 2])
    noise = directory / 'random.pt'
    # random, but the same bytes every run (a test that fails only sometimes is a failing one);
    # the first byte is the pickle PROTO opcode with a protocol number torch does not know,
    # the case that once made torch print a warning before refusing the file
    rng = random.Random(4096)
    noise.write_bytes(bytes([0x80, 95]) + bytes(rng.getrandbits(8) for _ in range(4094)))
    return {'truncated': truncated, 'random': noise}


def groundtruth_motion(bag: PathLike):
    """The ground-truth motion of a committed ``gt_*`` bag in the world (its camera-frame
    motion composed with the camera pose), as a :class:`~mocap_core.data.motion.Motion` with
    the bag's contact labels (30 fps)."""
    import numpy as np

    from .bag_io import BagReader, deserialize
    from .data.motion import Motion
    from .ros_conversions import motion_to_pose
    from .rotations import quat_multiply, quat_to_matrix
    from .topics import GROUNDTRUTH_CAMERA_POSE, GROUNDTRUTH_CONTACTS, GROUNDTRUTH_MOTION
    poses, contacts, cam = [], [], None
    with BagReader(bag) as reader:
        for m in reader.messages(topics=[GROUNDTRUTH_MOTION, GROUNDTRUTH_CONTACTS,
                                         GROUNDTRUTH_CAMERA_POSE]):
            msg = deserialize(m.data, m.msgtype)
            if m.topic == GROUNDTRUTH_MOTION:
                poses.append(motion_to_pose(msg))
            elif m.topic == GROUNDTRUTH_CONTACTS:
                contacts.append(np.asarray(msg.position) > 0.5)
            else:
                o, p = msg.pose.orientation, msg.pose.position
                cam = (np.array([o.x, o.y, o.z, o.w]), np.array([p.x, p.y, p.z]))
    q, t = cam
    rot = np.stack([p.rotations for p in poses])
    rot[:, 0] = quat_multiply(np.broadcast_to(q, rot[:, 0].shape), rot[:, 0])
    root = np.stack([p.root_position for p in poses]) @ np.asarray(quat_to_matrix(q)).T + t
    return Motion(Path(bag).name, 30.0, poses[0].skeleton, rot, root, np.stack(contacts))


def random_walk_poses(n: int, seed: int = 0, start=(0.0, 0.0, 0.95), step=(0.04, 0.0, 0.0)):
    """``n`` poses of the default skeleton with random limb rotations (0.2 rad per axis)
    and a root moving from ``start`` by ``step`` (m) per frame: test input for the stages."""
    import numpy as np

    from .pose import Pose
    from .rotations import axis_angle_to_matrix, matrix_to_quat
    from .skeleton import NUM_JOINTS, Skeleton

    rng = np.random.default_rng(seed)
    rot = np.zeros((n, NUM_JOINTS, 4))
    rot[..., 3] = 1.0
    rot[:, 1:] = matrix_to_quat(axis_angle_to_matrix(0.2 * rng.standard_normal(
        (n, NUM_JOINTS - 1, 3))))
    sk = Skeleton.default()
    return [Pose(sk, rot[i], np.asarray(start, float) + i * np.asarray(step, float))
            for i in range(n)]


def textured_floor_view(R_wc, C, K, size=(640, 480), seed: int = 3):
    """A synthetic camera image of a textured floor (the plane z = 0 of a z-up world, a 20 x
    20 m texture of random rectangles centred on the origin; the sky a uniform grey) seen
    from ``C`` (3,) m with the optical frame's orientation ``R_wc`` (3, 3, optical ->
    world) through intrinsics ``K`` (3, 3): the camera-motion tests' scene with a known
    metric camera path. ``size``: (width, height) pixels. Returns a BGR uint8 image."""
    import cv2
    import numpy as np

    key = (seed,)
    tex = _FLOOR_TEXTURES.get(key)
    if tex is None:
        rng = np.random.default_rng(seed)
        tex = np.full((2000, 2000, 3), 90, np.uint8)
        for _ in range(2500):
            x, y = rng.integers(0, 2000, 2)
            w, h = rng.integers(5, 60, 2)
            c = tuple(int(v) for v in rng.integers(0, 255, 3))
            cv2.rectangle(tex, (int(x), int(y)), (int(x + w), int(y + h)), c, -1)
        tex = cv2.GaussianBlur(tex, (3, 3), 0)
        _FLOOR_TEXTURES[key] = tex
    R_cw = np.asarray(R_wc, dtype=np.float64).T
    t = -R_cw @ np.asarray(C, dtype=np.float64)
    S = np.array([[0.01, 0.0, -10.0], [0.0, 0.01, -10.0], [0.0, 0.0, 1.0]])  # pixel -> m
    K = np.asarray(K, dtype=np.float64)
    Hm = K @ np.column_stack([R_cw[:, 0], R_cw[:, 1], t]) @ S
    W, H = size
    img = cv2.warpPerspective(tex, Hm, (W, H), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=(200, 200, 200))
    # the floor behind the camera maps into the image too: paint the sky above the horizon
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    rays = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(K).T @ R_cw
    img[rays[..., 2] >= -0.02] = 200
    return img


_FLOOR_TEXTURES: Dict[tuple, Any] = {}


def upright_keypoints(facing_camera: bool = True, cx: float = 320.0, top: float = 60.0,
                      height: float = 300.0, conf: float = 0.9):
    """(23, 3) image keypoints (u, v px, confidence) of an upright person ``height`` px tall
    from ``top``, centred on ``cx``: the left points on the image's right when
    ``facing_camera`` (labels facing the camera), else on its left; shoulders at 0.2 and hips
    at 0.5 of the height."""
    import numpy as np

    from .skeleton import KEYPOINT_INDEX, NUM_KEYPOINTS

    kp = np.zeros((NUM_KEYPOINTS, 3))
    kp[:, 0] = cx
    kp[:, 1] = np.linspace(top, top + height, NUM_KEYPOINTS)
    kp[:, 2] = conf
    s = 1.0 if facing_camera else -1.0
    for name, i in KEYPOINT_INDEX.items():
        if name.startswith('left_'):
            kp[i, 0] = cx + s * 0.12 * height
        elif name.startswith('right_'):
            kp[i, 0] = cx - s * 0.12 * height
    for part, at in (('shoulder', 0.2), ('hip', 0.5)):
        kp[[KEYPOINT_INDEX[f'left_{part}'], KEYPOINT_INDEX[f'right_{part}']], 1] = \
            top + at * height
    return kp

