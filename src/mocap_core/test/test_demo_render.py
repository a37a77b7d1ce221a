"""Pieces of the demo rendering: frame matching by stamp, the orthographic skeleton view,
the report text."""

import numpy as np
import pytest

from mocap_core.demo_render import SkeletonView, report_markdown, video_frame_indices
from mocap_core.pose import Pose
from mocap_core.run_report import PipelineRun, StageData
from mocap_core.skeleton import Skeleton


def test_video_frame_indices_from_stamps():
    fps = 23.976
    stamps = 1_000_000_000 + np.round(np.array([0, 1, 2, 5, 95]) * 1e9 / fps).astype(np.int64)
    np.testing.assert_array_equal(video_frame_indices(stamps, stamps[0], fps), [0, 1, 2, 5, 95])


def test_skeleton_view_keeps_the_body_in_the_panel_and_up_is_up():
    pose = Pose.rest(Skeleton.default())
    joints = pose.joint_positions()[None].repeat(3, axis=0)
    joints[1, :, 0] += 1.0                                   # walks 1 m forward
    view = SkeletonView(joints, np.array([1.0, 0.0, 0.0]), 200, 'side', floor_z=0.0)
    px = np.array([[view.to_px(p) for p in frame] for frame in joints])
    assert px.min() >= 0 and px.max() < 200
    head, pelvis = pose.joint_names.index('head'), 0
    assert px[0, head, 1] < px[0, pelvis, 1]                 # image y grows downwards
    assert px[1, pelvis, 0] > px[0, pelvis, 0]               # forward is to the right
    contacts = np.stack(list(pose.contact_positions().values()))
    img = view.draw(joints[0], contacts, np.array([[0, 0, 350.0], [0, 0, 0.0]]), 700.0)
    assert img.shape == (200, 200, 3) and (img < 255).any()


def test_report_lists_stages_and_nodes():
    n = 4
    stage = StageData(np.arange(n, dtype=np.int64), np.zeros((n, 18, 3)), np.zeros((n, 4, 3)),
                      np.ones((n, 10)), np.zeros((n, 3)))
    run = PipelineRun(np.arange(n, dtype=np.int64) * 33_000_000, np.zeros((n, 23, 3)),
                      stages={'lifter': stage},
                      diagnostics={'lifter: lifter': {'frames_in': '4', 'frames_out': '4'}})
    plaus = {'lifter': {'frames': 4.0, 'bone_spread_mm': 0.0, 'skeleton_final_from_frame': 0.0,
                        'bone_spread_final_mm': 0.0, 'jitter_mm_s2': float('nan')}}
    text = report_markdown(run, plaus, {}, 'A run', ['note one'], wall_s=2.0)
    assert text.startswith('# A run') and '- note one' in text
    assert '| lifter: lifter | 4 | 4 |' in text and '| lifter | 4 | 0.0 |' in text
    assert '2.0 frames/s' in text
    assert 'stature' not in text                 # no stature in the table: no line
    plaus['lifter']['stature_m'] = 1.734
    text = report_markdown(run, plaus, {}, 'A run', [], wall_s=2.0)
    assert "The person's stature from the lifted skeleton: 1.73 m" in text


def _walking_run(n=150, period=30, mass=70.0):
    """A physics stage whose feet alternate: each foot loaded for 60 % of a 1 s stride with a
    vertical force of 1 BW, its sagittal ankle torque 1.5 N m/kg while loaded."""
    from mocap_core.run_report import StageData
    t = np.arange(n)
    stamps = t.astype(np.int64) * 33_333_333
    grf = np.zeros((n, 2, 3))
    names = ['left_ankle_ry', 'right_ankle_ry']
    efforts = np.zeros((n, 2))
    for side, shift in ((0, 0), (1, period // 2)):
        on = ((t - shift) % period) < 0.6 * period
        on &= t >= shift
        grf[on, side, 2] = mass * 9.81
        efforts[on, side] = 1.5 * mass
    physics = StageData(stamps, np.zeros((n, 18, 3)), np.zeros((n, 4, 3)), np.zeros((n, 9)),
                        np.zeros((n, 3)))
    return PipelineRun(stamps, np.zeros((n, 23, 3)), {'physics': physics}, grf=grf,
                       efforts=efforts, effort_names=names, body_mass=mass)


def test_gait_cycles_of_the_physics_forces(tmp_path):
    from mocap_core.demo_render import gait_cycles, plot_gait
    run = _walking_run()
    cycles = gait_cycles(run)
    assert cycles is not None and cycles['strides'] >= 6
    m = cycles['grf_bw'].mean(axis=0)
    assert m[:55].min() == pytest.approx(1.0) and m[65:95].max() == pytest.approx(0.0)
    assert cycles['moments_per_kg']['ankle'].mean(axis=0).max() == pytest.approx(1.5)
    assert plot_gait(run, tmp_path / 'gait.png').stat().st_size > 10000
    # no body mass, or a person who never lifts a foot: no gait plot
    run.body_mass = float('nan')
    assert gait_cycles(run) is None
    standing = _walking_run()
    standing.grf[:, :, 2] = 350.0
    assert gait_cycles(standing) is None and plot_gait(standing, tmp_path / 'x.png') is None
