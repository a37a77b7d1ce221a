"""Synthetic scenes of several people seen by one camera, with the truth of who is who
(no ROS imports).

Motion clips (:class:`~mocap_core.data.motion.Motion`, world z up) are placed on the floor so
that their paths cross in front of a static camera; their 23 layout keypoints
(:func:`~mocap_core.data.synth2d.keypoints_3d`) are projected into the image. What a detector
would give is then made from them:

* **occlusion**: a keypoint of a person farther from the camera that falls on the body of a
  nearer person (within ``limb_width`` x that person's height of one of its bones, in the
  image) is not seen; a person with fewer than ``min_visible`` keypoints seen is not detected
  at all;
* **the image border**: points outside the image are not seen (people enter and leave);
* **entering and leaving**: an actor exists only in its ``[start, stop)`` frames;
* **detector noise**: pixel noise proportional to the person's height, keypoints dropped at
  random, and one-frame false detections (``blip_rate`` per frame);
* **row order**: shuffled every frame, as detectors do not keep one.

The truth is kept beside: for every output row, the index of the actor it came from (-1 for
a false detection). :func:`identity_metrics` scores a tracker's ids against it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..camera import CameraIntrinsics
from ..kinematics import forward_kinematics
from ..rotations import axis_angle_to_quat, quat_multiply
from ..skeleton import KEYPOINT_EDGES, NUM_KEYPOINTS
from .motion import Motion
from .synth2d import VirtualCamera, keypoints_3d, look_at


@dataclass(frozen=True)
class Actor:
    """One person of a scene: a motion turned by ``yaw`` (rad, about world z) and moved so that
    its root at frame ``anchor_frame`` of the clip is at ``anchor`` (x, y; m). The actor is in
    the scene for the scene frames ``[start, stop)`` (``stop`` None: until the clip ends);
    scene frame ``start`` shows clip frame ``clip_start``."""

    motion: Motion
    yaw: float = 0.0
    anchor: Tuple[float, float] = (0.0, 0.0)
    anchor_frame: Optional[int] = None     # default: the middle of the clip
    start: int = 0
    stop: Optional[int] = None
    clip_start: int = 0


@dataclass
class Scene:
    """A synthetic multi-person keypoint stream.

    Attributes:
        keypoints: per frame, a (P_t, 23, 3) array (u px, v px, confidence), rows shuffled.
        truth: per frame, (P_t,) int actor index of each row (-1: a false detection).
        clean: (F, A, 23, 3) keypoints of every actor before occlusion and noise (confidence 0
            where the actor is absent or the point is outside the image).
        depth: (F, A) distance of each actor's pelvis from the camera (m; inf when absent).
        camera: the camera.
        fps: frame rate (Hz).
        joints: (F, A, J, 3) every actor's joint positions in the camera's optical frame (m;
            NaN where the actor is absent), the 3D truth per person.
    """

    keypoints: List[np.ndarray]
    truth: List[np.ndarray]
    clean: np.ndarray
    depth: np.ndarray
    camera: VirtualCamera
    fps: float
    joints: Optional[np.ndarray] = None

    @property
    def num_frames(self) -> int:
        return len(self.keypoints)

    def stamps_s(self) -> np.ndarray:
        return np.arange(self.num_frames) / self.fps


def place(actor: Actor) -> Tuple[np.ndarray, np.ndarray]:
    """(F, J, 4) rotations and (F, 3) root positions of ``actor``'s clip in the scene's world."""
    m = actor.motion
    q = axis_angle_to_quat(np.array([0.0, 0.0, actor.yaw]))
    c, s = np.cos(actor.yaw), np.sin(actor.yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    rot = np.array(m.rotations, dtype=np.float64)
    rot[:, 0] = quat_multiply(np.broadcast_to(q, rot[:, 0].shape), rot[:, 0])
    root = m.root_positions @ R.T
    k = m.num_frames // 2 if actor.anchor_frame is None else actor.anchor_frame
    shift = np.array([actor.anchor[0], actor.anchor[1], 0.0]) - np.array(
        [root[k, 0], root[k, 1], 0.0])
    return rot, root + shift


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, 2) points, (S, 2) segment starts and ends -> (N, S) distances (px)."""
    ab = b - a
    t = np.einsum('nsk,sk->ns', p[:, None, :] - a[None], ab) / np.maximum(
        np.sum(ab * ab, axis=-1), 1e-9)
    t = np.clip(t, 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(p[:, None, :] - closest, axis=-1)


def make_scene(actors: Sequence[Actor], frames: int, camera: VirtualCamera,
               rng: np.random.Generator, fps: float = 30.0, limb_width: float = 0.06,
               min_visible: int = 6, noise: float = 0.004, drop_rate: float = 0.03,
               blip_rate: float = 0.02, shuffle: bool = True) -> Scene:
    """Build a :class:`Scene` (module docstring). ``noise`` is the pixel noise's standard
    deviation as a fraction of the person's height in the image; ``drop_rate`` the chance that
    a seen keypoint is reported unseen."""
    A = len(actors)
    W, H = camera.intrinsics.width, camera.intrinsics.height
    clean = np.zeros((frames, A, NUM_KEYPOINTS, 3))
    depth = np.full((frames, A), np.inf)
    joints = np.full((frames, A, actors[0].motion.skeleton.num_joints if A else 0, 3), np.nan)
    for a, actor in enumerate(actors):
        rot, root = place(actor)
        kp3 = keypoints_3d(actor.motion.skeleton, rot, root)
        sk = actor.motion.skeleton
        pos3 = forward_kinematics(sk.parents, sk.offsets, rot, root).positions
        stop = frames if actor.stop is None else min(actor.stop, frames)
        for f in range(actor.start, stop):
            k = actor.clip_start + f - actor.start
            if k >= len(kp3):
                break
            pc = camera.world_to_camera(kp3[k])
            if np.any(pc[:, 2] <= 0.2):
                continue
            uv = camera.intrinsics.project(pc)
            inside = (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
            clean[f, a, :, :2] = uv
            clean[f, a, :, 2] = inside.astype(float)
            depth[f, a] = float(np.linalg.norm(camera.world_to_camera(root[k])))
            joints[f, a] = camera.world_to_camera(pos3[k])
    edges = np.array(KEYPOINT_EDGES)
    out_kp: List[np.ndarray] = []
    out_truth: List[np.ndarray] = []
    for f in range(frames):
        seen = clean[f, :, :, 2] > 0
        heights = np.array([np.ptp(clean[f, a, seen[a], 1]) if seen[a].sum() >= 2 else 0.0
                            for a in range(A)])
        vis = seen.copy()
        order = np.argsort(depth[f])                    # nearest first
        for i, near in enumerate(order):
            if not np.isfinite(depth[f, near]) or seen[near].sum() < 2:
                continue
            pts = clean[f, near, :, :2]
            ok = seen[near][edges[:, 0]] & seen[near][edges[:, 1]]
            if not np.any(ok):
                continue
            a_pts, b_pts = pts[edges[ok, 0]], pts[edges[ok, 1]]
            radius = limb_width * max(heights[near], 1.0)
            for far in order[i + 1:]:
                if not np.isfinite(depth[f, far]):
                    continue
                d = _segment_distance(clean[f, far, :, :2], a_pts, b_pts).min(axis=1)
                vis[far] &= d > radius
        rows, truth = [], []
        for a in range(A):
            if vis[a].sum() < min_visible:
                continue
            kp = clean[f, a].copy()
            kp[:, 2] = vis[a] * rng.uniform(0.6, 1.0, NUM_KEYPOINTS)
            kp[:, :2] += rng.normal(0.0, noise * max(heights[a], 1.0), (NUM_KEYPOINTS, 2))
            kp[rng.random(NUM_KEYPOINTS) < drop_rate, 2] = 0.0
            kp[kp[:, 2] == 0] = 0.0
            rows.append(kp)
            truth.append(a)
        if rng.random() < blip_rate:                    # a one-frame false detection
            h = rng.uniform(0.1, 0.4) * H
            c = rng.uniform([0.1 * W, 0.3 * H], [0.9 * W, 0.7 * H])
            kp = np.zeros((NUM_KEYPOINTS, 3))
            kp[:, 0] = c[0] + rng.uniform(-0.2, 0.2, NUM_KEYPOINTS) * h
            kp[:, 1] = c[1] + rng.uniform(-0.5, 0.5, NUM_KEYPOINTS) * h
            kp[:, 2] = rng.uniform(0.4, 0.9, NUM_KEYPOINTS)
            rows.append(kp)
            truth.append(-1)
        idx = rng.permutation(len(rows)) if shuffle else np.arange(len(rows))
        out_kp.append(np.array(rows, dtype=np.float64).reshape(-1, NUM_KEYPOINTS, 3)[idx])
        out_truth.append(np.array(truth, dtype=int)[idx])
    return Scene(out_kp, out_truth, clean, depth, camera, fps, joints)


def crossing_camera(width: int = 1280, height: int = 720, distance: float = 7.0,
                    camera_height: float = 1.6, fov_deg: float = 70.0,
                    target: Tuple[float, float] = (0.0, 0.0)) -> VirtualCamera:
    """A static camera on the -y side of ``target``, ``distance`` m away, looking at it from
    ``camera_height`` m (aimed at 1 m above the floor)."""
    intr = CameraIntrinsics.from_fov(width, height, fov_deg)
    pos = np.array([target[0], target[1] - distance, camera_height])
    return VirtualCamera(intr, look_at(pos, np.array([target[0], target[1], 1.0])), pos)


def identity_metrics(truth: Sequence[np.ndarray], ids: Sequence[Dict[int, int]]
                     ) -> Dict[str, float]:
    """Score a tracker's identities against a scene's truth.

    Args:
        truth: per frame, (P_t,) actor index per input row (-1 for a false detection).
        ids: per frame, ``{input row: track id}`` for the rows the tracker published.

    Returns a dict: ``person_frames`` (rows of real actors), ``covered`` (of those, given an
    id), ``switches`` (an actor's id differs from the id it had the last time it was covered,
    CLEAR-MOT's identity switch), ``switches_per_1000``, ``fragments`` (an actor's coverage
    resumes after a gap), ``ids_per_actor`` (mean distinct ids per actor), ``false_ids``
    (ids that were given to a false detection), ``shared`` (frames where one id covers two
    actors at once, 0 by construction of a one-to-one tracker: a check of the glue).
    """
    last: Dict[int, int] = {}
    covered_last: Dict[int, bool] = {}
    seen_ids: Dict[int, set] = {}
    person_frames = covered = switches = fragments = shared = 0
    false_ids: set = set()
    for tr, got in zip(truth, ids):
        used: Dict[int, int] = {}
        present = set()
        for row, actor in enumerate(np.asarray(tr).tolist()):
            tid = got.get(row)
            if actor < 0:
                if tid is not None:
                    false_ids.add(tid)
                continue
            present.add(actor)
            person_frames += 1
            if tid is None:
                covered_last[actor] = False
                continue
            covered += 1
            if tid in used and used[tid] != actor:
                shared += 1
            used[tid] = actor
            seen_ids.setdefault(actor, set()).add(tid)
            if actor in last and last[actor] != tid:
                switches += 1
            if actor in covered_last and not covered_last[actor]:
                fragments += 1
            last[actor] = tid
            covered_last[actor] = True
    return {
        'person_frames': float(person_frames),
        'covered': covered / max(person_frames, 1),
        'switches': float(switches),
        'switches_per_1000': 1000.0 * switches / max(person_frames, 1),
        'fragments': float(fragments),
        'ids_per_actor': float(np.mean([len(v) for v in seen_ids.values()])) if seen_ids
        else 0.0,
        'false_ids': float(len(false_ids)),
        'shared': float(shared),
    }


def scene_actors(walk_a: Motion, walk_b: Motion, stand: Motion
                 ) -> Dict[str, Tuple[List[Actor], int, VirtualCamera]]:
    """The actors, frame count and camera of each scene of :func:`crossing_scenes` (which
    see), for the keypoint scenes and for rendered video (:mod:`mocap_core.render.people`)."""
    cam = crossing_camera()
    n_ab = min(walk_a.num_frames, walk_b.num_frames)
    # a walker whose path starts outside the picture: anchored at its first frame 2.5 m
    # beyond the border of the camera's view at that depth
    half = 7.0 * np.tan(np.radians(35.0))
    return {
        'cross2': ([Actor(walk_a, 0.0, (0.0, 0.0)), Actor(walk_b, np.pi, (0.0, 1.0))],
                   n_ab, cam),
        'cross3': ([Actor(walk_a, 0.0, (0.0, 0.0)), Actor(walk_b, np.pi, (0.0, 1.0)),
                    Actor(stand, 0.0, (0.2, 2.2))], n_ab, cam),
        'enter_leave': ([Actor(walk_a, 0.0, (-half - 1.0, 0.5), anchor_frame=0),
                         Actor(walk_b, np.pi, (half + 1.0, -0.5), anchor_frame=0, start=40),
                         Actor(stand, np.pi / 2, (0.5, -2.5), start=60, stop=140)],
                        n_ab + 40, cam),
    }


def crossing_scenes(walk_a: Motion, walk_b: Motion, stand: Motion, rng: np.random.Generator,
                    **scene_kwargs) -> Dict[str, Scene]:
    """The standard set of multi-person test scenes, made from two walking clips (walking
    along the clip's +x) and one clip of a person standing in place:

    * ``cross2``: two people walk towards each other across the image, one 1 m behind the
      other; the nearer hides the farther as they pass.
    * ``cross3``: the same two, and the standing person behind the point where they cross,
      hidden by each in turn.
    * ``enter_leave``: one walker enters the picture from the left border, the other enters
      from the right 40 frames later and passes in front; the standing person appears in front
      of both for the middle of the scene and leaves again (rows appear and vanish).

    Extra keyword arguments go to :func:`make_scene`.
    """
    return {name: make_scene(actors, frames, cam, rng, **scene_kwargs)
            for name, (actors, frames, cam) in scene_actors(walk_a, walk_b, stand).items()}
