"""FrameSmoother: zero-phase Gaussian smoothing of lifted frames with a fixed delay."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocap_core.pose import Pose
from mocap_core.skeleton import NUM_JOINTS, Skeleton
from mocap_lifter.online import LiftedFrame
from mocap_lifter.output_smoothing import FrameSmoother, smooth_along_time

SKELETON = Skeleton.default()


def frame(i, rotations, root, contacts=None):
    c = np.full(4, 0.1 * (i % 10)) if contacts is None else contacts
    return LiftedFrame(1000 * i, Pose(SKELETON, rotations, root), c, i > 5, float(root[2]))


def turning(n, rate_deg=3.0, noise_deg=0.0, seed=0):
    """Every joint turning about z at a constant rate (plus noise), the root moving on a
    straight line: (frames, true rotations (n, J, 4))."""
    rng = np.random.default_rng(seed)
    truth, frames = [], []
    for i in range(n):
        r = Rotation.from_euler('z', rate_deg * i, degrees=True)
        q_true = np.tile(r.as_quat(), (NUM_JOINTS, 1))
        noise = Rotation.from_rotvec(np.radians(noise_deg) * rng.normal(size=(NUM_JOINTS, 3)))
        q = (noise * Rotation.from_quat(q_true)).as_quat()
        truth.append(q_true)
        root = np.array([0.01 * i, -0.02 * i, 3.0 + 0.005 * i])
        frames.append(frame(i, q, root))
    return frames, np.array(truth)


def run(smoother, frames, group=1):
    out = []
    for k in range(0, len(frames), group):
        out += smoother.push(frames[k:k + group])
    return out + smoother.flush()


def test_delay_and_every_frame_once_in_order():
    frames, _ = turning(20)
    s = FrameSmoother(2.0)
    assert s.radius == 4
    got = []
    for i, f in enumerate(frames):
        got += s.push([f])
        assert len(got) == max(0, i + 1 - 4) and s.pending() == min(i + 1, 4)
    got += s.flush()
    assert [f.stamp_ns for f in got] == [f.stamp_ns for f in frames]
    assert s.pending() == 0 and s.flush() == []


def test_grouping_does_not_change_the_output():
    """Frame by frame (live) and in chunks (offline) give the same frames."""
    frames, _ = turning(30, noise_deg=2.0)
    a = run(FrameSmoother(1.5), frames, 1)
    b = run(FrameSmoother(1.5), frames, 7)
    assert len(a) == len(b) == 30
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.pose.rotations, y.pose.rotations)
        np.testing.assert_array_equal(x.pose.root_position, y.pose.root_position)


def test_a_linear_root_and_a_steady_turn_pass_unchanged_inside():
    """Symmetric weights keep a straight-line root exactly and a constant-rate turn to second
    order; the centre frame keeps its stamp, contacts and skeleton flag."""
    frames, truth = turning(25)
    got = run(FrameSmoother(2.0), frames)
    for i in range(4, 21):
        np.testing.assert_allclose(got[i].pose.root_position, frames[i].pose.root_position,
                                   atol=1e-12)
        assert got[i].depth == pytest.approx(frames[i].pose.root_position[2])
        ang = (Rotation.from_quat(got[i].pose.rotations[0]).inv()
               * Rotation.from_quat(truth[i, 0])).magnitude()
        assert np.degrees(ang) < 0.05
        np.testing.assert_array_equal(got[i].contacts, frames[i].contacts)
        assert got[i].skeleton_fixed == frames[i].skeleton_fixed
    # at the ends the window is cut: a one-sided mean lags the straight line
    assert not np.allclose(got[0].pose.root_position, frames[0].pose.root_position)


def test_noise_is_reduced():
    frames, truth = turning(200, noise_deg=3.0, seed=1)
    got = run(FrameSmoother(2.0), frames)

    def err(fs):
        return np.mean([np.degrees((Rotation.from_quat(f.pose.rotations).inv()
                                    * Rotation.from_quat(t)).magnitude())
                        for f, t in zip(fs[10:-10], truth[10:-10])])

    assert err(got) < 0.5 * err(frames)


def test_opposite_quaternion_signs_average_as_one_rotation():
    frames, _ = turning(12)
    flipped = [frame(i, -f.pose.rotations if i % 2 else f.pose.rotations,
                     f.pose.root_position) for i, f in enumerate(frames)]
    a = run(FrameSmoother(2.0), frames)
    b = run(FrameSmoother(2.0), flipped)
    for x, y in zip(a, b):
        d = np.abs(np.sum(x.pose.rotations * y.pose.rotations, axis=-1))
        np.testing.assert_allclose(d, 1.0, atol=1e-12)


def test_bad_parameters():
    with pytest.raises(ValueError, match='sigma'):
        FrameSmoother(0.0)
    with pytest.raises(ValueError, match='radius'):
        FrameSmoother(1.0, radius=0)


def test_batch_smoothing_of_sequences_shorter_than_the_window():
    for T in (1, 2, 3, 5):
        x = np.arange(T, dtype=float)[:, None] * [1.0, 2.0]
        out = smooth_along_time(x, 2.0)              # radius 4: every window is cut
        assert out.shape == x.shape and np.all(np.isfinite(out))
        assert out[0, 0] <= out[-1, 0]


def _small_lifter_input(seed: int, period_ns: int):
    """A small random MotioNet, a 640 x 480 camera, and 40 random keypoint frames whose
    stamps have a 5-s gap after the 20th (the lifter resets there)."""
    from mocap_core.camera import CameraIntrinsics
    from mocap_lifter.model import LifterConfig, MotioNet

    model = MotioNet(LifterConfig(channels=32, fusion_blocks=2, skeleton_channels=16,
                                  dropout=0.0)).eval()
    intr = CameraIntrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
    rng = np.random.default_rng(seed)
    kp = np.concatenate([rng.uniform(200, 400, (40, 23, 2)), np.ones((40, 23, 1))], -1)
    stamps = [period_ns * i for i in range(20)] + [5_000_000_000 + period_ns * i
                                                   for i in range(20)]
    return model, intr, kp, stamps


def test_online_lifter_with_output_smoothing_through_a_gap():
    """A gap resets the lifter: the frames before it are all emitted (smoothed, window cut
    at the gap), then the new segment starts; every stamp once, in order."""
    from mocap_lifter.online import OnlineLifter

    model, intr, kp, stamps = _small_lifter_input(2, 33_000_000)
    online = OnlineLifter(model, 'windowed', output_sigma=2.0)
    assert online.delay == online.latency + 4
    got, events = [], []
    for s, k in zip(stamps, kp):
        frames, event = online.push(s, k, intr)
        got += frames
        events.append(event)
    got += online.flush()
    assert events.count('gap') == 1
    assert [f.stamp_ns for f in got] == stamps and online.pending() == 0


def test_batch_smoothing_matches_the_stream_on_the_root():
    frames, _ = turning(30, noise_deg=2.0)
    roots = np.array([f.pose.root_position for f in frames])
    roots[:, 0] += np.random.default_rng(3).normal(0, 0.01, 30)
    frames = [frame(i, f.pose.rotations, r) for i, (f, r) in enumerate(zip(frames, roots))]
    got = np.array([f.pose.root_position for f in run(FrameSmoother(1.5), frames)])
    np.testing.assert_allclose(smooth_along_time(roots, 1.5), got, atol=1e-12)


def test_the_root_gets_its_own_width():
    """Rotations smoothed with ``sigma``, the root with ``root_sigma``; the delay is the
    larger radius, and each part is what a smoother of its own width alone gives."""
    frames, _ = turning(40, noise_deg=3.0, seed=4)
    roots = np.array([f.pose.root_position for f in frames])
    roots[:, 2] += np.random.default_rng(5).normal(0, 0.03, 40)     # depth noise
    frames = [frame(i, f.pose.rotations, r) for i, (f, r) in enumerate(zip(frames, roots))]
    s = FrameSmoother(1.0, root_sigma=3.0)
    assert s.radius == 6
    got = run(s, frames, 5)
    rot_alone = run(FrameSmoother(1.0), frames)
    np.testing.assert_allclose([f.pose.rotations for f in got],
                               [f.pose.rotations for f in rot_alone], atol=1e-12)
    np.testing.assert_allclose([f.pose.root_position for f in got],
                               smooth_along_time(roots, 3.0), atol=1e-12)
    assert [f.depth for f in got] == [f.pose.root_position[2] for f in got]
    # the wider root window takes out more of the depth noise than the rotations' width
    narrow = np.array([f.pose.root_position[2] for f in rot_alone])
    wide = np.array([f.pose.root_position[2] for f in got])
    assert np.abs(np.diff(wide, 2)).mean() < 0.5 * np.abs(np.diff(narrow, 2)).mean()


def test_rotations_left_alone_with_sigma_zero():
    frames, _ = turning(20, noise_deg=3.0)
    got = run(FrameSmoother(0.0, root_sigma=2.0), frames, 3)
    np.testing.assert_array_equal([f.pose.rotations for f in got],
                                  [f.pose.rotations for f in frames])
    with pytest.raises(ValueError):
        FrameSmoother(0.0, root_sigma=0.0)
    with pytest.raises(ValueError):
        FrameSmoother(1.0, root_sigma=-1.0)


def test_the_unsmoothed_frames_come_earlier_and_as_the_network_gave_them():
    """take_unsmoothed: every stamp once, in order, before the same frame comes out smoothed
    (by the smoothing's radius), through a gap; the same frames as without smoothing; a
    frame filled in for a dropped one (network_rate_hz) is not among them."""
    from mocap_lifter.online import OnlineLifter

    model, intr, kp, stamps = _small_lifter_input(3, 33_333_333)

    def run(**kw):
        online = OnlineLifter(model, 'windowed', **kw)
        smoothed, raw, first_raw, first_smoothed = [], [], {}, {}
        for k, (s, x) in enumerate(zip(stamps, kp)):
            smoothed += online.push(s, x, intr)[0]
            raw += online.take_unsmoothed()
            for f in raw:
                first_raw.setdefault(f.stamp_ns, k)
            for f in smoothed:
                first_smoothed.setdefault(f.stamp_ns, k)
        smoothed += online.flush()
        raw += online.take_unsmoothed()
        return online, smoothed, raw, first_raw, first_smoothed

    online, smoothed, raw, first_raw, first_smoothed = run(output_sigma=2.0)
    assert [f.stamp_ns for f in raw] == [f.stamp_ns for f in smoothed] == stamps
    # released earlier: by the smoothing's radius (4 frames) where no gap intervenes
    assert first_smoothed[stamps[5]] - first_raw[stamps[5]] == online.delay - online.latency
    _, plain, _, _, _ = run(output_sigma=0.0)
    for a, b in zip(raw, plain):
        np.testing.assert_allclose(a.pose.rotations, b.pose.rotations, atol=1e-6)
    assert max(np.abs(a.pose.rotations - b.pose.rotations).max()
               for a, b in zip(smoothed, plain)) > 1e-3
    # a frame dropped from the stream: the network gets a filled-in one, never returned
    online = OnlineLifter(model, 'windowed', output_sigma=2.0, network_rate_hz=30.0)
    kept = [k for k in range(20) if k != 8]
    raw = []
    for k in kept:
        online.push(stamps[k], kp[k], intr)
        raw += online.take_unsmoothed()
    online.flush()
    raw += online.take_unsmoothed()
    assert online.filled_frames == 1 and [f.stamp_ns for f in raw] == [stamps[k] for k in kept]
