"""Figures of one pipeline run, read from its output bag (``mocap process`` or a recording of
the live nodes): what the demo report prints and what the integration tests check.

:func:`load_run` reads the stages' topics into arrays keyed by header stamp;
:func:`plausibility` measures what needs no ground truth (bone-length spread, penetration of
the floor, foot skating, jitter, ground reaction forces against body weight);
:func:`accuracy` compares the lifter and physics stages with the ground truth of a
ground-truth bag (``/mocap/groundtruth/*``, camera optical frame).

Units: positions in metres in the arrays, figures in millimetres where the key says ``_mm``.
Frames: lifter = camera optical frame, physics = floor frame (z up, floor z = 0; its pose in the
camera frame is ``/mocap/physics/floor``), world = the GMR world frame (z up).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

import numpy as np

from . import pose_metrics as M
from . import topics as T
from .skeleton import CONTACT_POINT_NAMES, NUM_JOINTS, Skeleton

STAGES = ('lifter', 'physics', 'world')


@dataclass
class StageData:
    """One stage's per-frame output, frames in stamp order."""

    stamps: np.ndarray                          # (N,) int64 ns
    joints: np.ndarray                          # (N, J, 3) m
    contact_points: np.ndarray                  # (N, 4, 3) heel/toe l/r, m
    bone_groups: np.ndarray                     # (N, G) bone-group lengths of the skeleton, m
    root: np.ndarray                            # (N, 3) m
    frame_id: str = ''


@dataclass
class PipelineRun:
    """The arrays of one output bag (empty stages are absent from ``stages``)."""

    keypoint_stamps: np.ndarray
    keypoints: np.ndarray                       # (N, 23, 3) u, v, confidence of person 0
    stages: Dict[str, StageData] = field(default_factory=dict)
    contacts: Optional[np.ndarray] = None       # (N_lifter, 4) lifter probabilities
    grf: Optional[np.ndarray] = None            # (N_physics, 2, 3) left/right force, N
    efforts: Optional[np.ndarray] = None        # (N_physics, E) joint torques, N m
    effort_names: List[str] = field(default_factory=list)
    floor_rotation: Optional[np.ndarray] = None  # (N_physics, 3, 3) p_cam = R p_floor + t
    floor_translation: Optional[np.ndarray] = None
    body_mass: float = float('nan')
    gt_stamps: Optional[np.ndarray] = None
    gt_joints: Optional[np.ndarray] = None      # (N, J, 3) camera frame
    gt_contacts: Optional[np.ndarray] = None    # (N, 4) 0/1
    diagnostics: Dict[str, Dict[str, str]] = field(default_factory=dict)
    #: several people: every person's keypoint rows per keypoint frame, ``(rows (P, 23, 3),
    #: ids (P,))`` (ids 1.. in row order for a cloud without ids)
    people_keypoints: List[tuple] = field(default_factory=list)
    #: several people: ``{id: (stamps (N,), root (N, 3) m)}`` of the world stage's combined
    #: motion (empty without it)
    world_people: Dict[int, tuple] = field(default_factory=dict)

    @property
    def person_ids(self) -> List[int]:
        """Every id of the run (several people), in order."""
        ids = {int(i) for _, row_ids in self.people_keypoints for i in row_ids if i > 0}
        return sorted(ids | set(self.world_people))


def _read(bag: Path, wanted: Dict[str, Callable[[Any], Any]]) -> Dict[str, list]:
    from .bag_io import BagReader, deserialize

    out: Dict[str, list] = {t: [] for t in wanted}
    with BagReader(bag) as reader:
        present = [t for t in wanted if t in reader.topics]
        for m in reader.messages(topics=present):
            out[m.topic].append(wanted[m.topic](deserialize(m.data, m.msgtype)))
    return out


def load_run(bag: Path | str) -> PipelineRun:
    """Read a pipeline output bag (raises BagError for an unreadable one)."""
    from . import ros_conversions as rc
    from .ros_conversions import stamp_to_ns

    def stamped(convert):
        return lambda msg: (stamp_to_ns(msg.header.stamp), convert(msg), msg.header.frame_id)

    def pose_entry(msg):
        pose = rc.motion_to_pose(msg)
        cps = pose.contact_positions()
        return (pose.joint_positions(), np.stack([cps[n] for n in CONTACT_POINT_NAMES]),
                pose.skeleton.group_lengths(), np.asarray(pose.root_position, float))

    def floor_entry(msg):
        from scipy.spatial.transform import Rotation

        q = msg.transform.rotation
        t = msg.transform.translation
        return (Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), np.array([t.x, t.y, t.z]))

    def diag_entry(msg):
        return {s.name: {kv.key: kv.value for kv in s.values} for s in msg.status}

    wanted: Dict[str, Callable[[Any], Any]] = {
        T.KEYPOINTS: stamped(lambda m: (rc.cloud_to_keypoints(m), rc.cloud_to_ids(m))),
        T.bodies_topic('world', 'motion'): stamped(lambda m: [
            (pid, np.asarray(pose.root_position, float))
            for pid, pose in rc.motion_to_bodies(m)]),
        T.LIFTER_CONTACTS: stamped(rc.msg_to_contacts),
        T.PHYSICS_GRF_LEFT: stamped(lambda m: rc.msg_to_wrench(m)[0]),
        T.PHYSICS_GRF_RIGHT: stamped(lambda m: rc.msg_to_wrench(m)[0]),
        T.PHYSICS_JOINT_STATES: stamped(lambda m: (list(m.name), np.array(m.effort))),
        T.PHYSICS_FLOOR: stamped(floor_entry),
        T.SKELETON_URDF: lambda m: m.data,
        T.GROUNDTRUTH_JOINTS3D: stamped(lambda m: rc.cloud_to_positions(m, NUM_JOINTS)),
        T.GROUNDTRUTH_CONTACTS: stamped(rc.msg_to_contacts),
        T.DIAGNOSTICS: diag_entry,
    }
    for stage in STAGES:
        wanted[f'/mocap/{stage}/motion'] = stamped(pose_entry)
    raw = _read(Path(bag), wanted)

    def arrays(entries):
        entries = sorted(entries, key=lambda e: e[0])
        return np.array([e[0] for e in entries], dtype=np.int64), [e[1] for e in entries]

    st, clouds = arrays(raw[T.KEYPOINTS])
    kp = [rows[0] for rows, _ in clouds]
    run = PipelineRun(st, np.stack(kp) if kp else np.zeros((0, 23, 3)))
    for rows, ids in clouds:
        if ids is None:
            seen = np.any(rows[..., 2] > 0, axis=-1)
            ids = np.where(seen, np.arange(1, len(rows) + 1), 0)
        run.people_keypoints.append((rows, np.asarray(ids)))
    by_id: Dict[int, list] = {}
    for stamp, bodies, _ in raw[T.bodies_topic('world', 'motion')]:
        for pid, root in bodies:
            by_id.setdefault(pid, []).append((stamp, root))
    for pid, entries in sorted(by_id.items()):
        entries.sort(key=lambda e: e[0])
        run.world_people[pid] = (np.array([e[0] for e in entries], dtype=np.int64),
                                 np.stack([e[1] for e in entries]))
    for stage in STAGES:
        entries = sorted(raw[f'/mocap/{stage}/motion'], key=lambda e: e[0])
        if not entries:
            continue
        run.stages[stage] = StageData(
            np.array([e[0] for e in entries], dtype=np.int64),
            np.stack([e[1][0] for e in entries]), np.stack([e[1][1] for e in entries]),
            np.stack([e[1][2] for e in entries]), np.stack([e[1][3] for e in entries]),
            entries[-1][2])
    if raw[T.LIFTER_CONTACTS]:
        run.contacts = np.stack(arrays(raw[T.LIFTER_CONTACTS])[1])
    left, right = raw[T.PHYSICS_GRF_LEFT], raw[T.PHYSICS_GRF_RIGHT]
    if left and len(left) == len(right):
        run.grf = np.stack([np.stack(arrays(left)[1]), np.stack(arrays(right)[1])], axis=1)
    if raw[T.PHYSICS_JOINT_STATES]:
        values = arrays(raw[T.PHYSICS_JOINT_STATES])[1]
        run.effort_names = values[-1][0]
        if all(len(v[1]) == len(run.effort_names) for v in values):
            run.efforts = np.stack([v[1] for v in values])
    if raw[T.PHYSICS_FLOOR]:
        values = arrays(raw[T.PHYSICS_FLOOR])[1]
        run.floor_rotation = np.stack([v[0] for v in values])
        run.floor_translation = np.stack([v[1] for v in values])
    if raw[T.SKELETON_URDF]:
        run.body_mass = _urdf_mass(raw[T.SKELETON_URDF][-1])
    if raw[T.GROUNDTRUTH_JOINTS3D]:
        run.gt_stamps, gt = arrays(raw[T.GROUNDTRUTH_JOINTS3D])
        run.gt_joints = np.stack(gt)
    if raw[T.GROUNDTRUTH_CONTACTS]:
        run.gt_contacts = np.stack(arrays(raw[T.GROUNDTRUTH_CONTACTS])[1])
    for d in raw[T.DIAGNOSTICS]:
        run.diagnostics.update(d)
    return run


def _urdf_mass(urdf: str) -> float:
    import re

    return float(sum(float(v) for v in re.findall(r'<mass\s+value="([^"]+)"', urdf)))


def _jitter_mm_per_s2(joints: np.ndarray, dt: float) -> float:
    """Mean joint acceleration magnitude, mm/s^2 (smoothness; real motion has some)."""
    return M.jitter_mm(joints) / dt ** 2 if len(joints) >= 3 else float('nan')


def _stature(group_lengths: np.ndarray) -> float:
    """The stature (m) of a skeleton of (G,) bone-group lengths (NaN if it is not one)."""
    try:
        return Skeleton.from_group_lengths(group_lengths).stature()
    except ValueError:
        return float('nan')


def plausibility(run: PipelineRun, contact_threshold: float = 0.5) -> Dict[str, Dict[str, float]]:
    """Per stage: frames; the stature (m, :meth:`~mocap_core.skeleton.Skeleton.stature`) of
    the last skeleton; bone-length spread (mm) of the skeleton over the run (the lifter
    refines it during its first ``skeleton_frames`` frames, then holds it), the number of
    skeleton changes, the frame of the last one, and the spread of the bone lengths measured
    on the joint positions from then on; jitter (mm/s^2); foot skating (mm per frame of a
    contact point in contact, horizontal); for the physics stage: floor penetration (mm,
    deepest contact point below z = 0) and the mean total vertical GRF over body weight on
    frames with force."""
    out: Dict[str, Dict[str, float]] = {}
    for name, s in run.stages.items():
        dt = float(np.median(np.diff(s.stamps))) * 1e-9 if len(s.stamps) > 1 else 1 / 30
        changed = np.flatnonzero(np.abs(np.diff(s.bone_groups, axis=0)).max(axis=1) > 1e-6)
        last = int(changed[-1]) + 1 if len(changed) else 0
        f: Dict[str, float] = {
            'frames': float(len(s.stamps)),
            'bone_spread_mm': float(1000 * np.ptp(s.bone_groups, axis=0).max()),
            'skeleton_changes': float(len(changed)),
            'skeleton_final_from_frame': float(last),
            # from the joint positions, once the skeleton is final: 0 when every stage keeps
            # the bone lengths it was given
            'bone_spread_final_mm': M.bone_length_spread_mm(s.joints[last:]),
            'jitter_mm_s2': _jitter_mm_per_s2(s.joints, dt),
            'stature_m': _stature(s.bone_groups[-1]) if len(s.bone_groups) else float('nan'),
        }
        up = 1 if name == 'lifter' else 2           # camera optical frame: y down
        if name == 'lifter':
            height = -s.contact_points[..., 1]       # relative only: no floor here
        else:
            height = s.contact_points[..., 2]
        contact = None
        if run.contacts is not None and len(run.contacts) == len(s.stamps):
            contact = run.contacts >= contact_threshold
        if name != 'lifter':
            low = height < height.min(axis=None) + 0.05 if name == 'world' else height < 0.05
            contact = low if contact is None else contact & low
        if contact is not None:
            f['skating_mm'] = M.foot_skating_mm(s.contact_points, contact, up)
        if name == 'physics':
            f['penetration_mm'] = float(max(0.0, -1000 * height.min()))
            if run.grf is not None and np.isfinite(run.body_mass):
                fz = run.grf[..., 2].sum(axis=1)
                loaded = fz > 1.0
                f['grf_over_weight'] = (float(fz[loaded].mean() / (run.body_mass * 9.81))
                                        if loaded.any() else float('nan'))
                f['frames_with_force'] = float(loaded.sum())
        if name == 'world':
            f['root_path_m'] = float(np.linalg.norm(np.diff(s.root[:, :2], axis=0),
                                                    axis=-1).sum())
            # end-to-end distance over path length: 1 for a straight walk, ~0 on the spot
            end = float(np.linalg.norm(s.root[-1, :2] - s.root[0, :2]))
            f['root_straightness'] = end / f['root_path_m'] if f['root_path_m'] > 0 \
                else float('nan')
        out[name] = f
    return out


def _matched(stamps: np.ndarray, ref: np.ndarray):
    common, i, j = np.intersect1d(stamps, ref, return_indices=True)
    return i, j


def accuracy(run: PipelineRun) -> Dict[str, Dict[str, float]]:
    """Lifter and physics against ``/mocap/groundtruth/joints3d`` (matched by stamp): MPJPE,
    PA-MPJPE (mm), and the lifter's heel/toe contact accuracy. Empty without ground truth."""
    out: Dict[str, Dict[str, float]] = {}
    if run.gt_joints is None:
        return out
    for name in ('lifter', 'physics'):
        s = run.stages.get(name)
        if s is None:
            continue
        i, j = _matched(s.stamps, run.gt_stamps)
        pred = s.joints[i]
        if name == 'physics':
            if run.floor_rotation is None or len(run.floor_rotation) != len(s.stamps):
                continue                               # no camera <- floor transform
            pred = np.einsum('nij,nkj->nki', run.floor_rotation[i], pred) + \
                run.floor_translation[i][:, None]
        gt = run.gt_joints[j]
        out[name] = {'frames': float(len(i)), 'mpjpe_mm': M.mpjpe_mm(pred, gt),
                     'pa_mpjpe_mm': M.pa_mpjpe_mm(pred, gt)}
        if name == 'lifter' and run.contacts is not None and run.gt_contacts is not None \
                and len(run.contacts) == len(s.stamps) and len(run.gt_contacts) == len(
                    run.gt_stamps):
            out[name]['contact_accuracy'] = M.contact_accuracy(run.contacts[i],
                                                               run.gt_contacts[j])
    return out
