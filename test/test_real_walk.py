"""The real moving-camera walk (``glamr/pexels-walking-dynamic-5738706.mp4`` of the shared data: a
woman walks away from a following camera for 7.4 s, about 8-10 m): the regression test of the
world stage on real footage (docs/global.md). Skipped where the shared data is absent.

What holds today is asserted: the camera is seen to move, its translation is measured over the
physics floor once the floor exists (from about the second second), and the world path then
follows the camera. The path goals of the world-frame issue (6-12 m, straightness >= 0.8) are
not met (4.1 m, 0.97 in session 62; 4.1 m, 0.83 in session 52; 4.3 m, 0.78 in session 38;
3.8 m, 0.75 with the
pure-rotation camera turn of before;
the first second, before the floor, is GMR's alone) and are
kept as a strict expected failure, which turns into a failure the day they are met so that the
mark is removed. The clip is slowed down about twice (6.5 steps in 7.4 s, 53 steps/min): the
camera's measured path is 4.4-4.9 m, as 6.5 steps of 0.65-0.75 m give (docs/global.md)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from mocap_core.data.splits import shared_data_dir

VIDEO = shared_data_dir() / 'videos' / 'glamr' / 'pexels-walking-dynamic-5738706.mp4'

pytestmark = pytest.mark.skipif(not VIDEO.exists(), reason=f'{VIDEO} not present')


@pytest.fixture(scope='module')
def walk(tmp_path_factory):
    from mocap_core.bag_io import BagReader, deserialize
    from mocap_core.ros_conversions import odometry_to_camera_motion
    from mocap_core.run_report import load_run, plausibility

    out = tmp_path_factory.mktemp('walk') / 'bag'
    res = subprocess.run([sys.executable, '-m', 'mocap_core.cli.mocap', 'process', str(VIDEO),
                          '-o', str(out), '--no-progress'],
                         capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    states = []
    with BagReader(out) as reader:
        for m in reader.messages(topics=['/mocap/camera/motion']):
            states.append(odometry_to_camera_motion(deserialize(m.data, m.msgtype))[0])
    run = load_run(out)
    return run, plausibility(run)['world'], states


def test_the_following_camera_is_seen_to_move_and_nothing_is_fused(walk):
    run, world, states = walk
    assert len(states) >= 170                         # one estimate per frame (178 frames)
    assert states.count('moving') > 0.5 * len(states), states
    assert states.count('static') < 0.2 * len(states), states
    diag = run.diagnostics['gmr: gmr']
    assert diag['camera_mode'] == 'auto'
    # once the physics floor reaches the keypoint node (about 30 frames in), the camera's
    # translation is measured and those frames are fused; before it GMR is alone
    frames = dict(kv.rsplit(' ', 1) for kv in diag['camera_motion_frames'].split(', '))
    assert int(frames.get('moving (translation measured)', 0)) >= 100, diag
    assert int(diag['unfused_frames']) <= 40, diag
    # the estimate's guard against made-up plane / floor turns (docs/global.md, "What the
    # camera-motion estimate could not see") has (almost) nothing to refuse on real footage
    assert int(run.diagnostics['keypoints: keypoints']['camera_turns_refused']) <= 5


def test_the_world_path_follows_the_camera_once_it_is_measured(walk):
    """From the second second on the path is the person's walk: end to end more than 2 m
    (the camera went 3.5 m, the person came 0.5 m closer to it), nearly straight."""
    run, _, _ = walk
    root = run.stages['world'].root[40:, :2]
    path = float(np.linalg.norm(np.diff(root, axis=0), axis=1).sum())
    end = float(np.linalg.norm(root[-1] - root[0]))
    assert end > 2.0 and end / path > 0.85, (end, path)


@pytest.mark.xfail(strict=True, reason='the world path of a person walking away from a '
                   'following camera: 4.1 m (goal 6-12 m; straightness 0.97 meets its 0.8): '
                   'the clip plays about twice slowed, the camera\'s measured path is '
                   '4.4-4.9 m, and the first second, before the physics floor exists, is GMR '
                   'alone (docs/global.md)')
def test_the_world_path_is_the_walk(walk):
    _, world, _ = walk
    assert 6.0 <= world['root_path_m'] <= 12.0 and world['root_straightness'] >= 0.8, world
