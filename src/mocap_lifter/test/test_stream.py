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


# --- frames missing from the stream (network_rate_hz) -------------------------------------------
def _lifter(fill: float, mode: str = 'windowed', **kw) -> OnlineLifter:
    import torch
    torch.manual_seed(0)
    model = MotioNet(LifterConfig(**SMALL, causal=(mode == 'causal'))).eval()
    return OnlineLifter(model, mode, skeleton_frames=20, network_rate_hz=fill, **kw)


INTR = CameraIntrinsics(1280, 720, 1000.0, 1000.0, 639.5, 359.5)


def _lift(lifter: OnlineLifter, indices) -> list:
    frames = []
    for k in indices:
        frames += lifter.push(T0 + k * DT, _people(k)[0], INTR)[0]
    return frames + lifter.flush()


@pytest.mark.parametrize('mode', ['windowed', 'causal'])
def test_a_stream_without_gaps_is_lifted_as_without_the_fill(mode):
    a = _lift(_lifter(30.0, mode, output_sigma=1.0), range(40))
    b = _lift(_lifter(0.0, mode, output_sigma=1.0), range(40))
    assert [f.stamp_ns for f in a] == [f.stamp_ns for f in b] == [T0 + k * DT for k in range(40)]
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.pose.rotations, y.pose.rotations)
        np.testing.assert_array_equal(x.pose.root_position, y.pose.root_position)


@pytest.mark.parametrize('mode', ['windowed', 'causal'])
def test_gaps_are_filled_and_only_the_frames_received_come_out(mode):
    """Every second and third frame of a 30 fps stream, a 25 fps stretch (gaps of 1.2
    periods: not filled) and a gap beyond max_gap_s (a reset, not filled): the frames
    received come out once each, in order; the filled ones are lifted as context only."""
    kept = list(range(0, 20, 2)) + list(range(20, 41, 3))
    stamps = [T0 + k * DT for k in kept] + [T0 + 40 * DT + j * 40_000_000
                                            for j in range(1, 6)]
    stamps += [stamps[-1] + 2_000_000_000 + j * DT for j in range(4)]
    lifter = _lifter(30.0, mode, output_sigma=1.0)
    out, pending = [], []
    for j, s in enumerate(stamps):
        frames, _ = lifter.push(s, _people(j)[0], INTR)
        out += frames
        pending.append(lifter.pending())
    out += lifter.flush()
    assert [f.stamp_ns for f in out] == stamps
    # gaps of 2 periods (10 of them, one frame each), 3 periods (6, two each) and the
    # step into the 25 fps stretch (3.2 periods: two)
    assert lifter.filled_frames == 10 + 2 * 6 + 2
    assert lifter.pending() == 0 and max(pending) <= lifter.delay + 1
    # without the fill, the same frames come out, lifted differently
    plain = _lifter(0.0, mode, output_sigma=1.0)
    other = []
    for j, s in enumerate(stamps):
        other += plain.push(s, _people(j)[0], INTR)[0]
    other += plain.flush()
    assert [f.stamp_ns for f in other] == stamps and plain.filled_frames == 0
    assert not np.allclose(np.stack([f.pose.rotations for f in out]),
                           np.stack([f.pose.rotations for f in other]))


def test_a_negative_network_rate_is_refused():
    with pytest.raises(ValueError, match='network_rate_hz'):
        _lifter(-1.0)


@pytest.mark.parametrize('mode', ['windowed', 'causal'])
def test_a_faster_stream_is_thinned_and_every_frame_comes_out(mode):
    """60 frames/s, then a gap of three periods, then 60 frames/s to the end: every second
    frame goes to the network, the gap is filled, and every frame received comes out once,
    in order; a thinned frame's rotations lie between its neighbours' (slerp), the ones
    after the last network frame hold it."""
    from mocap_core.rotations import quat_angle

    half = DT // 2
    stamps = [T0 + j * half for j in range(41)]
    stamps += [stamps[-1] + 3 * DT + j * half for j in range(30)]
    lifter = _lifter(30.0, mode, output_sigma=1.0)
    out = []
    for j, s in enumerate(stamps):
        out += lifter.push(s, _people(j)[0], INTR)[0]
        assert lifter.pending() == j + 1 - len(out)        # every frame received, once
    out += lifter.flush()
    assert [f.stamp_ns for f in out] == stamps
    assert lifter.thinned_frames == 20 + 15 and lifter.filled_frames == 2
    assert lifter.pending() == 0
    for a, b, c in zip(out[0:40:2], out[1:41:2], out[2:41:2]):
        # halfway, joint by joint: slerp at t = 0.5 between the network frames around it
        np.testing.assert_allclose(quat_angle(a.pose.rotations, b.pose.rotations),
                                   0.5 * quat_angle(a.pose.rotations, c.pose.rotations),
                                   atol=1e-6)
        np.testing.assert_allclose(b.pose.root_position,
                                   0.5 * (a.pose.root_position + c.pose.root_position),
                                   atol=1e-9)
    np.testing.assert_allclose(quat_angle(out[-1].pose.rotations, out[-2].pose.rotations),
                               0.0, atol=1e-6)     # the last one held


def test_thinned_frames_before_a_reset_and_a_stamp_going_back_are_not_lost():
    """A thinned frame waiting when the stream resets (a gap beyond max_gap_s) comes out
    before the new segment; after an idle flush, a stamp at or before a thinned frame already
    published is a stamp going backwards (a new segment), never a duplicate."""
    half = DT // 2
    lifter = _lifter(30.0)
    stamps = [T0 + j * half for j in range(31)]
    out = []
    for j, s in enumerate(stamps):
        out += lifter.push(s, _people(j)[0], INTR)[0]
    late = stamps[-1] + 2_000_000_000
    frames, event = lifter.push(late, _people(0)[0], INTR)
    out += frames
    assert event == 'gap' and [f.stamp_ns for f in out] == stamps
    out += lifter.flush()                           # idle flush: the new segment's frame
    assert [f.stamp_ns for f in out] == stamps + [late]
    frames, event = lifter.push(late, _people(1)[0], INTR)
    assert event == 'backwards'


def test_the_node_counts_what_gone_persons_filled():
    from mocap_lifter.online import PeopleStreams

    def make():
        return _lifter(30.0)

    streams = PeopleStreams(make, StreamIntrinsics(60.0, warmup_frames=2), 0, 1.0, 0.5, 4)
    for k in range(0, 20, 2):
        streams.push(T0 + k * DT, _people(k), ids=np.array([1]))
    filled_before = streams.rate_counts()[0]
    streams.push(T0 + 200 * DT, np.zeros((1, 23, 3)), ids=np.array([0]))  # 1 is gone
    assert filled_before > 0 and streams.rate_counts() == (filled_before, 0)


def test_filled_gaps_lift_a_walk_seen_at_a_third_of_its_rate_better():
    """A committed ground-truth walk (validation clip, the default weights) with two frames
    of every three missing: filling the gaps brings PA-MPJPE most of the way back to the
    all-frames figure (measured: 22.8 mm all frames, 65.4 as is, 27.8 filled;
    docs/benchmarks/lifter_drops.md)."""
    from pathlib import Path

    import torch

    from mocap_lifter.training.drops import kept_frames, lift_kept, read_bag
    from mocap_lifter.training.metrics import pa_mpjpe_mm
    from mocap_lifter.weights import default_weights, load_weights

    torch.set_num_threads(1)
    root = Path(__file__).resolve().parents[3]
    kp, intr, gt = read_bag(root / 'bags' / 'gt_bandai_walk_exhausted')
    model = load_weights(default_weights('windowed')).eval()
    kept = kept_frames('every 3rd frame (10 Hz)', len(kp), 0)
    as_is, n0 = lift_kept(model, kp, intr, kept, 0.0)
    filled, n1 = lift_kept(model, kp, intr, kept, 30.0)
    pa_as_is, pa_filled = pa_mpjpe_mm(as_is, gt[kept]), pa_mpjpe_mm(filled, gt[kept])
    print(f'PA-MPJPE as is {pa_as_is:.1f} mm, filled {pa_filled:.1f} mm')
    assert n0 == 0 and n1 == 2 * (len(kept) - 1)
    assert pa_filled < 0.6 * pa_as_is and pa_filled < 35.0


def test_hidden_keypoints_are_held_from_their_last_sighting_for_a_while():
    """hold_unseen_s: a keypoint of a seen person with confidence 0 whose last sighting lies
    in another person's box (hidden behind someone) takes its last seen position and
    confidence while that sighting is at most hold_unseen_s old; later, with the option off,
    or with nobody in front of it (a keypoint the detector dropped) it reaches the network
    unseen. A frame without the person is not filled."""
    import torch
    torch.manual_seed(0)
    model = MotioNet(LifterConfig(**SMALL)).eval()

    def run(hold, in_front=True):
        stream = LifterStream(OnlineLifter(model, 'windowed', skeleton_frames=20),
                              StreamIntrinsics(60.0, warmup_frames=5), person=0,
                              max_gap_s=1.0, hold_unseen_s=hold)
        got = []
        push = stream.lifter.push

        def spy(stamp_ns, keypoints, *a, **k):
            got.append(np.array(keypoints, copy=True))
            return push(stamp_ns, keypoints, *a, **k)
        stream.lifter.push = spy
        people = [_people(k) for k in range(20)]
        for k in range(10, 20):
            people[k][0, 5] = 0.0                      # keypoint 5 hidden from frame 10 on
        people[15] = np.zeros((1, 23, 3))              # nobody in frame 15
        u, v = people[9][0, 5, :2]
        # someone whose box covers keypoint 5's last sighting, or one beside it
        box = np.array([[u - 5, v - 5, u + 5, v + 5]]) if in_front else \
            np.array([[u + 20, v - 5, u + 40, v + 5]])
        for k, p in enumerate(people):
            stream.push(T0 + k * DT, p, box)
        stream.flush()
        return stream, got, people

    stream, got, people = run(0.1)                      # three frames at 30 frames/s
    assert len(got) == 20
    for k in (10, 11, 12):
        np.testing.assert_array_equal(got[k][5], people[9][0, 5])
    for k in range(13, 20):
        np.testing.assert_array_equal(got[k][5], 0.0)
    np.testing.assert_array_equal(got[15], 0.0)        # the absent person is not filled
    for k in range(20):                                 # every other keypoint as it came
        if k != 15:
            np.testing.assert_array_equal(np.delete(got[k], 5, axis=0),
                                          np.delete(people[k][0], 5, axis=0))
    assert stream.held_keypoints == 3
    for hold, in_front in ((0.0, True), (0.1, False)):  # off; dropped with nobody in front
        other, got_other, _ = run(hold, in_front)
        assert other.held_keypoints == 0
        for k in range(10, 20):
            np.testing.assert_array_equal(got_other[k][5], 0.0)
    with pytest.raises(ValueError, match='hold_unseen_s'):
        LifterStream(OnlineLifter(model, 'windowed'), StreamIntrinsics(60.0),
                     hold_unseen_s=-1.0)
