"""The node's streaming logic without ROS (mocap_lifter.online.LifterStream): a stream without
camera_info, the person leaving the picture, camera info arriving late, restarts."""

import numpy as np
import pytest

from mocap_core.camera import CameraIntrinsics
from mocap_lifter.intrinsics import StreamIntrinsics
from mocap_lifter.model import LifterConfig, MotioNet
from mocap_lifter.online import LifterStream, OnlineLifter

SMALL = dict(channels=16, fusion_blocks=1, skeleton_channels=8, dropout=0.0)
DT = 33_333_333
T0 = 1_700_000_000_000_000_000


def _stream(mode: str = 'windowed', warmup: int = 10) -> LifterStream:
    import torch
    torch.manual_seed(0)
    model = MotioNet(LifterConfig(**SMALL, causal=(mode == 'causal'))).eval()
    return LifterStream(OnlineLifter(model, mode, skeleton_frames=20),
                        StreamIntrinsics(60.0, warmup_frames=warmup), person=0, max_gap_s=1.0)


def _people(k: int, seed: int = 0) -> np.ndarray:
    """(1, 23, 3) keypoints of one person near the middle of a 1280 x 720 image, a little
    different every frame (so is their extent)."""
    rng = np.random.default_rng(seed * 1000 + k)
    kp = np.zeros((1, 23, 3))
    kp[0, :, 0] = 560 + 160 * rng.random(23) + 2 * k
    kp[0, :, 1] = 150 + 450 * rng.random(23)
    kp[0, :, 2] = 0.5 + 0.5 * rng.random(23)
    return kp


def _run(stream: LifterStream, people, t0: int = T0):
    frames, resets, errors = [], [], []
    for k, p in enumerate(people):
        step = stream.push(t0 + k * DT, p)
        frames += step.frames
        resets += step.resets
        errors += step.errors
    return frames, resets, errors


@pytest.mark.parametrize('mode', ['windowed', 'causal'])
def test_person_leaves_the_picture_without_camera_info(mode):
    """20 frames with the person, then 40 with every confidence 0, no camera_info: every frame
    is lifted (the empty ones through the network, as trained), no reset, no error."""
    stream = _stream(mode)
    people = [_people(k) for k in range(20)] + [np.zeros((1, 23, 3))] * 40
    frames, resets, errors = _run(stream, people)
    frames += stream.flush().frames
    assert errors == [] and resets == []
    assert [f.stamp_ns for f in frames] == [T0 + k * DT for k in range(60)]
    assert all(np.all(np.isfinite(f.pose.joint_positions())) for f in frames)
    assert stream.intrinsics.describe() == 'approximate 1280x720, fov 60 deg (from keypoints)'


def test_without_camera_info_the_window_fills_and_nothing_resets():
    """The keypoint extent changes every frame; the intrinsics do not: the windowed lifter
    emits every frame `latency` frames late and never resets."""
    stream = _stream('windowed', warmup=10)
    frames, resets, _ = _run(stream, [_people(k) for k in range(60)])
    assert resets == []
    assert len(frames) == 60 - stream.lifter.latency
    assert stream.lifter.frames_seen == 60
    assert stream.pending() == stream.lifter.latency


def test_frames_wait_for_the_estimate_then_flow_in_order():
    stream = _stream('causal', warmup=5)
    got = []
    for k in range(4):
        step = stream.push(T0 + k * DT, _people(k))
        assert step.frames == [] and step.dropped == ''
        got.append(step)
    assert stream.pending() == 4 and stream.intrinsics.current is None
    step = stream.push(T0 + 4 * DT, _people(4))          # the fifth frame fixes the estimate
    assert [f.stamp_ns for f in step.frames] == [T0 + k * DT for k in range(5)]
    assert len(stream.push(T0 + 5 * DT, _people(5)).frames) == 1   # then one per frame


def test_nobody_before_anyone_was_seen_is_dropped_and_stale_stamps_too():
    stream = _stream('causal', warmup=1)
    step = stream.push(T0, np.zeros((0, 23, 3)))
    assert step.nobody and step.dropped == 'nobody seen yet'
    assert stream.push(T0 + DT, _people(1)).frames
    assert stream.push(T0 + DT, _people(2)).dropped == 'keypoint stamp did not advance'
    assert stream.push(T0 + DT - 10_000_000, _people(2)).dropped   # a small step back
    step = stream.push(T0 + 2 * DT, np.zeros((1, 23, 3)))
    assert step.nobody and step.dropped == '' and len(step.frames) == 1


def test_camera_info_arriving_late_resets_once():
    stream = _stream('windowed', warmup=10)
    frames, resets, _ = _run(stream, [_people(k) for k in range(30)])
    stream.intrinsics.set_camera_info(CameraIntrinsics(1280, 720, 1000.0, 1000.0, 640.0, 360.0))
    more, resets2, _ = _run(stream, [_people(k) for k in range(30, 60)], T0 + 30 * DT)
    frames += more + stream.flush().frames
    assert resets + resets2 == ['intrinsics']
    assert [f.stamp_ns for f in frames] == [T0 + k * DT for k in range(60)]
    assert stream.intrinsics.describe() == 'camera_info'


def test_a_restarted_stream_flushes_the_old_one_and_estimates_again():
    stream = _stream('windowed', warmup=5)
    frames, _, _ = _run(stream, [_people(k) for k in range(60)])
    first = stream.intrinsics.current
    # the bag again from its start (stamps 2 s back), the person now at the image's right:
    # 1920 x 1080
    later = []
    for k in range(5):
        p = _people(k)
        p[0, :, 0] += 900
        p[0, :, 1] += 350
        later.append(p)
    step = stream.push(T0, later[0])
    assert step.jumped_back_s == pytest.approx(59 * DT * 1e-9)
    assert step.resets == ['backwards']
    assert [f.stamp_ns for f in frames + step.frames] == [T0 + k * DT for k in range(60)]
    for k in range(1, 5):
        stream.push(T0 + k * DT, later[k])
    assert stream.intrinsics.current != first
    assert (stream.intrinsics.current.width, stream.intrinsics.current.height) == (1920, 1080)
