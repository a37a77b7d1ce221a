"""The demo's pictures and report from a pipeline run (:class:`~.run_report.PipelineRun`; no
ROS imports): a video of the input frames with their 2D keypoints beside the reconstructed
skeleton of the world stage (side and front views, z up) with foot contacts and ground reaction
forces, plots of the root trajectory, vertical ground reaction forces and joint torques, and a
Markdown report.

Frame matching: a video frame's index is recovered from the keypoint stamps, which the keypoint
node sets to ``start + round(index * 1e9 / fps)`` for a video file (the first frame published is
index 0: the demo runs the video without dropping frames).
"""

from __future__ import annotations

from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np

from .run_report import PipelineRun
from .skeleton import CONTACT_POINT_NAMES, JOINT_NAMES, KEYPOINT_EDGES, KEYPOINT_NAMES, PARENTS

_BLUE, _ORANGE, _GREY = (200, 120, 30), (30, 140, 240), (150, 150, 150)   # BGR
_RED, _GREEN = (40, 40, 220), (60, 170, 60)


def _side_colour(name: str):
    return _BLUE if name.startswith('left') else _ORANGE if name.startswith('right') else _GREY


def _bgr(person_id: int) -> tuple:
    """The person's colour (:func:`~mocap_core.ros_conversions.person_color`) as OpenCV BGR."""
    from .ros_conversions import person_color
    r, g, b, _ = person_color(int(person_id))
    return (int(255 * b), int(255 * g), int(255 * r))


def draw_keypoints(image: np.ndarray, kp: np.ndarray, color: Optional[tuple] = None,
                   label: str = '', threshold: float = 0.3) -> np.ndarray:
    """Draw (23, 3) keypoints (u, v, confidence) on a BGR image (in place; returned): bones
    coloured by side, or all in ``color`` (BGR, e.g. one per person) with ``label`` above
    the highest point."""
    import cv2

    for a, b in KEYPOINT_EDGES:
        if kp[a, 2] >= threshold and kp[b, 2] >= threshold:
            cv2.line(image, (int(kp[a, 0]), int(kp[a, 1])), (int(kp[b, 0]), int(kp[b, 1])),
                     color or _side_colour(KEYPOINT_NAMES[b]), 2, cv2.LINE_AA)
    for u, v, c in kp:
        if c >= threshold:
            cv2.circle(image, (int(u), int(v)), 3, (255, 255, 255), -1, cv2.LINE_AA)
    seen = kp[:, 2] >= threshold
    if label and np.any(seen):
        top = int(np.argmin(np.where(seen, kp[:, 1], np.inf)))
        cv2.putText(image, label, (int(kp[top, 0]) - 15, int(kp[top, 1]) - 10),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.5, color or (255, 255, 255), 1, cv2.LINE_AA)
    return image


class SkeletonView:
    """Orthographic view of z-up skeletons onto a square panel with fixed scale.

    ``axis`` (3,) is the horizontal screen direction (unit, horizontal); screen up = +z."""

    def __init__(self, joints: np.ndarray, axis: np.ndarray, size: int, title: str,
                 floor_z: float) -> None:
        self.axis = np.asarray(axis, float) / np.linalg.norm(axis)
        self.size = size
        self.title = title
        self.floor_z = floor_z
        h = joints.reshape(-1, 3) @ self.axis
        z = joints.reshape(-1, 3)[:, 2]
        lo, hi = np.array([h.min(), min(z.min(), floor_z)]), np.array([h.max(), z.max()])
        span = float(max(hi - lo)) * 1.25 + 1e-6
        self.scale = size / span
        self.centre = (lo + hi) / 2

    def to_px(self, p: np.ndarray) -> tuple:
        h, z = float(p @ self.axis), float(p[2])
        x = self.size / 2 + (h - self.centre[0]) * self.scale
        y = self.size / 2 - (z - self.centre[1]) * self.scale
        return int(round(x)), int(round(y))

    def draw(self, joints: np.ndarray, contact_points: Optional[np.ndarray] = None,
             foot_forces: Optional[np.ndarray] = None, weight: float = 1.0) -> np.ndarray:
        """A panel: floor line, skeleton, contact points (red = carrying force) and vertical
        ground reaction force arrows (0.5 m per body weight) at each loaded foot."""
        import cv2

        img = np.full((self.size, self.size, 3), 255, np.uint8)
        fy = self.to_px(np.array([0.0, 0.0, self.floor_z]))[1]
        cv2.line(img, (0, fy), (self.size, fy), (120, 120, 120), 1)
        for j in range(1, len(joints)):
            cv2.line(img, self.to_px(joints[PARENTS[j]]), self.to_px(joints[j]),
                     _side_colour(JOINT_NAMES[j]), 3, cv2.LINE_AA)
        if contact_points is not None:
            for k, name in enumerate(CONTACT_POINT_NAMES):
                foot = 0 if name.startswith('left') else 1
                loaded = foot_forces is not None and foot_forces[foot, 2] > 1.0
                cv2.circle(img, self.to_px(contact_points[k]), 4, _RED if loaded else _GREEN,
                           -1, cv2.LINE_AA)
            if foot_forces is not None:
                for foot in (0, 1):
                    fz = foot_forces[foot, 2]
                    if fz <= 1.0:
                        continue
                    base = contact_points[2 * foot:2 * foot + 2].mean(axis=0)
                    tip = base + np.array([0.0, 0.0, 0.5 * fz / weight])
                    cv2.arrowedLine(img, self.to_px(base), self.to_px(tip), _RED, 2,
                                    cv2.LINE_AA, tipLength=0.15)
        cv2.putText(img, self.title, (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1,
                    cv2.LINE_AA)
        return img


def video_frame_indices(stamps: np.ndarray, first_stamp: int, fps: float) -> np.ndarray:
    """Frame index of each stamp of a video source (see the module doc)."""
    return np.round((np.asarray(stamps, np.int64) - int(first_stamp)) * fps / 1e9).astype(int)


def render_video(run: PipelineRun, video: Path, out: Path, sheet: Optional[Path] = None,
                 panel: Optional[int] = None, sheet_frames: int = 5) -> int:
    """Write ``out`` (MP4): each keypoint frame as the video frame with its keypoints beside
    side and front views of the world skeleton (empty views, labelled, where the world stage
    has no pose for it: before a person got an id, or while nobody is seen); and optionally
    ``sheet`` (PNG), a few frames with a skeleton stacked. Returns the number of frames
    written."""
    import cv2

    world = run.stages['world']
    cap = cv2.VideoCapture(str(video))
    if not cap.isOpened():
        raise ValueError(f'cannot open video {video}')
    fps = cap.get(cv2.CAP_PROP_FPS) or 30.0
    frames: List[np.ndarray] = []
    ok, img = cap.read()
    while ok:
        frames.append(img)
        ok, img = cap.read()
    cap.release()
    if not frames:
        raise ValueError(f'no frames in {video}')
    h, w = frames[0].shape[:2]
    panel = panel or h
    index = video_frame_indices(run.keypoint_stamps, run.keypoint_stamps[0], fps)
    kp_by_stamp = {int(s): k for s, k in zip(run.keypoint_stamps, run.keypoints)}
    world_at = {int(s): n for n, s in enumerate(world.stamps)}
    people_by_stamp = {int(s): p for s, p in zip(run.keypoint_stamps, run.people_keypoints)}
    # view axes from the body's facing at the first frame (hips: left - right)
    j = world.joints
    left = j[0, JOINT_NAMES.index('left_hip')] - j[0, JOINT_NAMES.index('right_hip')]
    left[2] = 0.0
    left /= max(np.linalg.norm(left), 1e-9)
    forward = np.cross(left, [0.0, 0.0, 1.0])
    floor_z = float(np.percentile(world.contact_points[..., 2].min(axis=1), 5))
    side = SkeletonView(j, forward, panel, 'world, side view', floor_z)
    front = SkeletonView(j, left, panel, 'world, front view', floor_z)  # as the camera sees it
    physics = run.stages.get('physics')
    grf_by_stamp = {}
    if physics is not None and run.grf is not None and len(run.grf) == len(physics.stamps):
        grf_by_stamp = {int(s): g for s, g in zip(physics.stamps, run.grf)}
    weight = run.body_mass * 9.81 if np.isfinite(run.body_mass) else 700.0
    writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*'mp4v'), fps,
                             (w + 2 * panel, h))
    composed, written = [], 0
    for stamp, i in zip(run.keypoint_stamps, index):
        if not 0 <= i < len(frames):
            continue
        left_img = frames[i].copy()
        people = people_by_stamp.get(int(stamp))
        if people is not None and len(run.person_ids) > 1:
            for rows_kp, pid in zip(*people):       # every person, one colour per id
                if pid > 0:
                    draw_keypoints(left_img, rows_kp, _bgr(pid), label=f'id {int(pid)}')
        else:
            kp = kp_by_stamp.get(int(stamp))
            if kp is not None:
                draw_keypoints(left_img, kp)
        cv2.putText(left_img, f'frame {i}  t = {i / fps:.2f} s', (8, 20),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
        n = world_at.get(int(stamp))
        if n is not None:
            forces = grf_by_stamp.get(int(stamp))
            views = [v.draw(j[n], world.contact_points[n], forces, weight)
                     for v in (side, front)]
        else:
            blank = np.full((panel, panel, 3), 40, np.uint8)
            cv2.putText(blank, 'no world pose for this frame', (8, 20),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.5, (200, 200, 200), 1, cv2.LINE_AA)
            views = [blank, blank]
        if panel != h:
            views = [cv2.resize(v, (panel, h)) for v in views]
        frame = np.hstack([left_img] + views)
        writer.write(frame)
        written += 1
        if n is not None:
            composed.append(frame)
    writer.release()
    if sheet is not None and composed:
        pick = np.linspace(0, len(composed) - 1, min(sheet_frames, len(composed))).round()
        cv2.imwrite(str(sheet), np.vstack([composed[int(k)] for k in pick]))
    return written


def plot_run(run: PipelineRun, out_dir: Path) -> Dict[str, Path]:
    """PNG plots: ``root_trajectory.png`` (world root, top view and height), ``grf.png``
    (vertical ground reaction force per foot with body weight), ``torques.png`` (hip, knee and
    ankle flexion torques), ``gait.png`` (:func:`plot_gait`, when the run has strides).
    Returns the files written."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    written: Dict[str, Path] = {}
    t0 = run.keypoint_stamps[0] if len(run.keypoint_stamps) else 0
    world = run.stages.get('world')
    if world is not None:
        t = (world.stamps - t0) * 1e-9
        fig, ax = plt.subplots(1, 2, figsize=(10, 4))
        if len(run.world_people) > 1:
            from .ros_conversions import person_color
            for pid, (_, root) in run.world_people.items():
                ax[0].plot(root[:, 0], root[:, 1], '-', color=person_color(pid)[:3],
                           label=f'person {pid}')
        ax[0].plot(world.root[:, 0], world.root[:, 1], '-', color='tab:blue')
        ax[0].plot(world.root[0, 0], world.root[0, 1], 'o', color='tab:green', label='start')
        ax[0].plot(world.root[-1, 0], world.root[-1, 1], 's', color='tab:red', label='end')
        ax[0].set_aspect('equal', adjustable='datalim')
        ax[0].set_xlabel('x (m)')
        ax[0].set_ylabel('y (m)')
        ax[0].set_title('world root, top view')
        ax[0].legend(fontsize=8)
        ax[1].plot(t, world.root[:, 2], label='root height (world z)')
        ax[1].set_xlabel('time (s)')
        ax[1].set_ylabel('m')
        ax[1].set_title('root height')
        fig.tight_layout()
        written['root_trajectory'] = out_dir / 'root_trajectory.png'
        fig.savefig(written['root_trajectory'], dpi=100)
        plt.close(fig)
    physics = run.stages.get('physics')
    if physics is not None and run.grf is not None and len(run.grf) == len(physics.stamps):
        t = (physics.stamps - t0) * 1e-9
        fig, ax = plt.subplots(figsize=(10, 3.5))
        ax.plot(t, run.grf[:, 0, 2], color='tab:blue', label='left foot')
        ax.plot(t, run.grf[:, 1, 2], color='tab:orange', label='right foot')
        ax.plot(t, run.grf[:, :, 2].sum(axis=1), color='k', lw=0.8, label='total')
        if np.isfinite(run.body_mass):
            ax.axhline(run.body_mass * 9.81, color='gray', ls='--',
                       label=f'body weight ({run.body_mass:.0f} kg)')
        ax.set_xlabel('time (s)')
        ax.set_ylabel('vertical GRF (N)')
        ax.legend(fontsize=8, loc='upper right')
        ax.set_title('ground reaction forces (physics stage)')
        fig.tight_layout()
        written['grf'] = out_dir / 'grf.png'
        fig.savefig(written['grf'], dpi=100)
        plt.close(fig)
    if physics is not None and run.efforts is not None:
        t = (physics.stamps - t0) * 1e-9
        names = [n for n in ('left_hip_ry', 'right_hip_ry', 'left_knee_ry', 'right_knee_ry',
                             'left_ankle_ry', 'right_ankle_ry') if n in run.effort_names]
        fig, axes = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
        for ax, joint in zip(axes, ('hip', 'knee', 'ankle')):
            for n in names:
                if f'_{joint}_' in n:
                    ax.plot(t, run.efforts[:, run.effort_names.index(n)],
                            color='tab:blue' if n.startswith('left') else 'tab:orange',
                            label=n)
            ax.set_ylabel('N m')
            ax.legend(fontsize=8, loc='upper right')
        axes[0].set_title('joint torques about the flexion (y) axis, physics stage')
        axes[-1].set_xlabel('time (s)')
        fig.tight_layout()
        written['torques'] = out_dir / 'torques.png'
        fig.savefig(written['torques'], dpi=100)
        plt.close(fig)
    gait = plot_gait(run, out_dir / 'gait.png')
    if gait is not None:
        written['gait'] = gait
    return written


def gait_cycles(run: PipelineRun, min_strides: int = 2) -> Optional[dict]:
    """The physics stage's vertical GRF (body weights) and sagittal hip, knee and ankle
    torques (N m/kg) over the gait cycle of each foot, averaged over strides: a stride runs
    from the frame the foot's vertical force rises above 5 % of the body weight to the next
    such frame (:mod:`mocap_core.gait`). None without a body mass or with fewer than
    ``min_strides`` strides (a person who does not walk)."""
    from .gait import heel_strikes, stride_curves
    physics = run.stages.get('physics')
    if (physics is None or run.grf is None or len(run.grf) != len(physics.stamps)
            or not np.isfinite(run.body_mass) or run.body_mass <= 0):
        return None
    weight = run.body_mass * 9.81
    grf, moments, strides = [], {}, 0
    for side, foot in enumerate(('left', 'right')):
        fz = run.grf[:, side, 2] / weight
        strikes = heel_strikes(fz > 0.05)
        curves = stride_curves(fz, strikes)
        if not len(curves):
            continue
        strides += len(curves)
        grf.append(curves)
        if run.efforts is not None and len(run.efforts) == len(physics.stamps):
            for joint in ('hip', 'knee', 'ankle'):
                name = f'{foot}_{joint}_ry'
                if name in run.effort_names:
                    tau = run.efforts[:, run.effort_names.index(name)] / run.body_mass
                    moments.setdefault(joint, []).append(stride_curves(tau, strikes))
    if strides < min_strides:
        return None
    return {'strides': strides, 'grf_bw': np.concatenate(grf),
            'moments_per_kg': {j: np.concatenate(c) for j, c in moments.items()}}


def plot_gait(run: PipelineRun, path: Path) -> Optional[Path]:
    """``gait.png``: :func:`gait_cycles` as mean +- std over strides, with the published
    normal-walking ranges (vertical GRF peaks 1.1-1.3 body weights; ankle plantarflexion
    peak about 1.5 N m/kg; sources in ``mocap_physics.training.gait``). None when the run
    has no strides."""
    cycles = gait_cycles(run)
    if cycles is None:
        return None
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    x = np.linspace(0, 100, cycles['grf_bw'].shape[1])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    m, sd = cycles['grf_bw'].mean(axis=0), cycles['grf_bw'].std(axis=0)
    axes[0].plot(x, m, color='tab:blue', label=f"mean of {cycles['strides']} strides")
    axes[0].fill_between(x, m - sd, m + sd, color='tab:blue', alpha=0.2, label='+- 1 std')
    axes[0].axhspan(1.1, 1.3, color='tab:green', alpha=0.15, label='published peaks')
    axes[0].set_xlabel('gait cycle of the foot (%)')
    axes[0].set_ylabel('vertical GRF (body weights)')
    axes[0].set_title('ground reaction force over the gait cycle')
    axes[0].legend(fontsize=8)
    for (joint, curves), colour in zip(cycles['moments_per_kg'].items(),
                                      ('tab:blue', 'tab:orange', 'tab:red')):
        axes[1].plot(x, curves.mean(axis=0), color=colour, label=joint)
    axes[1].axhspan(1.3, 1.6, color='tab:red', alpha=0.1,
                    label='published ankle peak (magnitude)')
    axes[1].axhspan(-1.6, -1.3, color='tab:red', alpha=0.1)
    axes[1].set_xlabel('gait cycle of the foot (%)')
    axes[1].set_ylabel('sagittal torque (N m/kg)')
    axes[1].set_title('joint torques over the gait cycle')
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


def _fmt(v: float, digits: int = 1) -> str:
    return 'n/a' if v is None or not np.isfinite(v) else f'{v:.{digits}f}'


def report_markdown(run: PipelineRun, plaus: Dict[str, Dict[str, float]],
                    acc: Dict[str, Dict[str, float]], title: str,
                    notes: Sequence[str] = (), wall_s: Optional[float] = None) -> str:
    """The run's Markdown report: frames, rates, per-stage processing time (from the nodes'
    final /diagnostics), plausibility and (with ground truth) accuracy."""
    n = len(run.keypoint_stamps)
    span = (run.keypoint_stamps[-1] - run.keypoint_stamps[0]) * 1e-9 if n > 1 else 0.0
    lines = [f'# {title}', '', f'- input: {n} keypoint frames over {span:.2f} s of stamps']
    if wall_s:
        lines.append(f'- wall time of the run: {wall_s:.1f} s ({n / wall_s:.1f} frames/s '
                     'achieved end to end)')
    lines.append(f'- body mass (URDF): {_fmt(run.body_mass)} kg')
    lines += [f'- {x}' for x in notes]
    if len(run.person_ids) > 1:
        lines += ['', '## Persons', '',
                  'One colour per id in the video and the root trajectory plot; the other '
                  'figures are the main person\'s (the one tracked longest).', '',
                  '| id | keypoint frames | world frames | world path (m) |', '|---|---|---|---|']
        for pid in run.person_ids:
            kf = sum(1 for _, ids in run.people_keypoints if pid in ids)
            stamps, root = run.world_people.get(pid, (np.zeros(0), np.zeros((0, 3))))
            path = float(np.sum(np.linalg.norm(np.diff(root[:, :2], axis=0), axis=1))) \
                if len(root) > 1 else 0.0
            lines.append(f'| {pid} | {kf} | {len(stamps)} | {path:.2f} |')
    lines += ['', '## Per node (final /diagnostics)', '',
              '| node | frames in | frames out | dropped | errors | processing median (ms) | '
              'p95 (ms) |', '|---|---|---|---|---|---|---|']
    for name, v in sorted(run.diagnostics.items()):
        lines.append(f"| {name} | {v.get('frames_in', '')} | {v.get('frames_out', '')} | "
                     f"{v.get('frames_dropped', '')} | {v.get('errors', '')} | "
                     f"{v.get('processing_ms_median', '')} | {v.get('processing_ms_p95', '')} |")
    lines += ['', '## Plausibility', '',
              '| stage | frames | bone-length spread, whole run (mm) | skeleton final from '
              'frame | spread after (mm) | jitter (m/s²) | foot skating (mm/frame) | '
              'penetration (mm) | mean GRF / weight |', '|---|---|---|---|---|---|---|---|---|']
    for stage, f in plaus.items():
        lines.append(
            f"| {stage} | {int(f['frames'])} | {_fmt(f['bone_spread_mm'])} | "
            f"{int(f['skeleton_final_from_frame'])} | {_fmt(f['bone_spread_final_mm'], 3)} | "
            f"{_fmt(f['jitter_mm_s2'] / 1000, 2)} | {_fmt(f.get('skating_mm', float('nan')))} "
            f"| {_fmt(f.get('penetration_mm', float('nan')), 2)} | "
            f"{_fmt(f.get('grf_over_weight', float('nan')), 2)} |")
    stature = plaus.get('lifter', {}).get('stature_m', float('nan'))
    if np.isfinite(stature):
        lines += ['', f"The person's stature from the lifted skeleton: {stature:.2f} m (the "
                  "lifter's estimate from the keypoints, unless `lifter.subject_height` was "
                  'given; a known stature, `--param lifter.subject_height=METRES`, sizes the '
                  'body and places it at the right depth: docs/lifter.md, "What the keypoints '
                  'cannot tell").']
    if acc:
        lines += ['', '## Accuracy against ground truth', '',
                  '| stage | frames | MPJPE (mm) | PA-MPJPE (mm) | contact accuracy |',
                  '|---|---|---|---|---|']
        for stage, f in acc.items():
            lines.append(f"| {stage} | {int(f['frames'])} | {_fmt(f['mpjpe_mm'])} | "
                         f"{_fmt(f['pa_mpjpe_mm'])} | "
                         f"{_fmt(f.get('contact_accuracy', float('nan')), 3)} |")
    lines += ['', 'Bone-length spread: the lifter refines the skeleton over its first '
              '`skeleton_frames` frames, then holds it; "spread after" is measured on the joint '
              'positions from then on (0 = one skeleton). Jitter: mean joint acceleration. '
              'Skating: horizontal motion of heel/toe points per frame while in contact. '
              'Penetration: deepest heel/toe point below the physics floor.', '']
    return '\n'.join(lines)
