"""The streaming encoder (mocap_lifter.streaming) gives the window pass's output frame by frame:
the shipped networks, windowed and causal, with and without the test-time flip, through
segment starts, gaps in the hips (features that change after the frame arrived), people who
leave the picture, resets and flushes."""

import numpy as np
import pytest
import torch

from mocap_core.camera import CameraIntrinsics
from mocap_lifter.model import LifterConfig, MotioNet
from mocap_lifter.online import OnlineLifter
from mocap_lifter.streaming import StreamingEncoder
from mocap_lifter.weights import default_weights, load_weights

DT = 33_333_333
T0 = 1_700_000_000_000_000_000
INTR = CameraIntrinsics(fx=900.0, fy=900.0, cx=640.0, cy=360.0, width=1280, height=720)
_HIPS = (11, 12)


def _walk(n: int, seed: int = 0) -> np.ndarray:
    """(n, 23, 3) keypoints of a person that moves smoothly across a 1280 x 720 image (a
    random smooth trajectory per keypoint around a body layout)."""
    rng = np.random.default_rng(seed)
    base = np.stack([560 + 160 * rng.random(23), 150 + 450 * rng.random(23)], axis=-1)
    t = np.arange(n)[:, None, None]
    phase = rng.random((1, 23, 2)) * 6.28
    kp = np.zeros((n, 23, 3))
    kp[..., :2] = base[None] + 25 * np.sin(0.2 * t + phase) + np.array([3.0, 0.5]) * t
    kp[..., 2] = 0.6 + 0.4 * rng.random((n, 23))
    return kp


def _lift(lifter: OnlineLifter, frames: np.ndarray, stamps=None):
    out = []
    stamps = [T0 + k * DT for k in range(len(frames))] if stamps is None else stamps
    for s, kp in zip(stamps, frames):
        got, _ = lifter.push(s, kp, INTR)
        out += got
    return out + lifter.flush()


def _compare(model, mode, frames, flip, stamps=None):
    a = OnlineLifter(model, mode, flip=flip, streaming=True)
    b = OnlineLifter(model, mode, flip=flip, streaming=False)
    assert a.streaming and not b.streaming
    fa, fb = _lift(a, frames, stamps), _lift(b, frames, stamps)
    assert [f.stamp_ns for f in fa] == [f.stamp_ns for f in fb]
    for x, y in zip(fa, fb):
        dot = np.abs(np.sum(x.pose.rotations * y.pose.rotations, axis=-1))
        assert np.all(1.0 - dot < 1e-5), float(np.max(1.0 - dot))
        np.testing.assert_allclose(x.pose.root_position, y.pose.root_position, atol=1e-4)
        np.testing.assert_allclose(x.contacts, y.contacts, atol=1e-4)
        np.testing.assert_allclose(x.pose.skeleton.offsets, y.pose.skeleton.offsets,
                                   atol=1e-5)
        assert x.skeleton_fixed == y.skeleton_fixed
    return a


@pytest.mark.parametrize('mode,flip', [('windowed', True), ('windowed', False),
                                       ('causal', False)])
def test_shipped_networks_stream_as_the_window_pass(mode, flip):
    model = load_weights(default_weights(mode), causal=(mode == 'causal'))
    frames = _walk(150)
    lifter = _compare(model, mode, frames, flip)
    assert lifter._stream.recomputed == 0


def test_hips_missing_at_the_start_and_in_a_long_gap():
    """Frames without hips take a later frame's root while no earlier one exists, and hold an
    earlier one in a gap: their features change after they arrived; the columns are redone."""
    model = load_weights(default_weights('windowed'))
    frames = _walk(160, seed=1)
    frames[:20, _HIPS, 2] = 0.0
    frames[60:100, _HIPS, 2] = 0.0
    frames[110:125] = 0.0                  # the person leaves the picture
    lifter = _compare(model, 'windowed', frames, True)
    assert lifter._stream.recomputed > 0


def test_gaps_and_resets_start_new_segments():
    model = load_weights(default_weights('windowed'))
    frames = _walk(120, seed=2)
    stamps = [T0 + k * DT for k in range(60)] + [T0 + (k + 200) * DT for k in range(60, 120)]
    _compare(model, 'windowed', frames, True, stamps)


def test_a_short_segment_and_a_custom_latency():
    model = load_weights(default_weights('windowed'))
    _compare(model, 'windowed', _walk(9, seed=3), True)           # shorter than the lag
    custom = OnlineLifter(model, 'windowed', latency=5)
    assert not custom.streaming                # exact only at the default look-ahead
    assert not OnlineLifter(model, 'windowed', chunk=4).streaming
    assert not OnlineLifter(model, 'windowed', smooth=1.0).streaming


def test_encoder_matches_the_network_on_random_weights():
    """A small random network with batch-norm statistics that are not the identity."""
    torch.manual_seed(0)
    for causal in (False, True):
        model = MotioNet(LifterConfig(channels=32, fusion_blocks=2, skeleton_channels=8,
                                      dropout=0.0, causal=causal))
        for m in model.modules():
            if isinstance(m, torch.nn.BatchNorm1d):
                m.running_mean.uniform_(-0.5, 0.5)
                m.running_var.uniform_(0.5, 2.0)
                m.weight.data.uniform_(0.5, 1.5)
                m.bias.data.uniform_(-0.2, 0.2)
        model.eval()
        enc = StreamingEncoder(model, rows=1)
        assert enc.lag == (0 if causal else model.cfg.receptive_field() // 2)
        x = torch.randn(1, 40, model.feature_mean.numel())
        with torch.no_grad():
            xn = ((x - model.feature_mean) / model.feature_std).transpose(1, 2)
            y = model.e_q.shrink(model.e_q.blocks(model.e_q.expand(xn))).transpose(1, 2)
        outs = []
        for n in range(40):
            lo = max(0, n + 1 - enc.field)
            o = enc.push(x[:, lo:n + 1].numpy())
            if o is not None:
                outs.append(o)
        got = np.stack(outs, axis=1)
        # the window pass over all 40 frames: its last `lag` frames read the right padding
        want = y[:, :40 - enc.lag].numpy()
        np.testing.assert_allclose(got, want, atol=1e-4)


def test_bad_window_shape_is_refused():
    model = load_weights(default_weights('windowed'))
    enc = StreamingEncoder(model, rows=2)
    with pytest.raises(ValueError, match='window must have shape'):
        enc.push(np.zeros((1, 3, 72)))
    with pytest.raises(ValueError, match='after 1 pushes'):
        enc.push(np.zeros((2, 3, 72)))
