"""The lifter on a CUDA device (the node's ``device:=cuda``): the same frames as on the CPU.

Skipped without a CUDA device (the CI machine has none). On a machine with one, the shipped
default weights lift 120 frames of smoothly moving keypoints frame by frame and in chunks, with
test-time flip and the output smoothing, on both devices; the poses agree to float32
rounding (an NVIDIA H200, session 33: 0.12 mm frame by frame, 0.16 mm in chunks).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason='no CUDA device')



def _keypoints(n: int = 120) -> np.ndarray:
    """(n, 23, 3) keypoints: a person's joints moving smoothly, with confidences."""
    rng = np.random.default_rng(0)
    base = rng.uniform(250, 400, (1, 23, 2))
    t = np.arange(n)[:, None, None] / 30.0
    uv = base + 20 * np.sin(2 * np.pi * 0.7 * t + rng.uniform(0, 6, (1, 23, 1)))
    return np.concatenate([uv, rng.uniform(0.6, 1.0, (n, 23, 1))], -1)


@pytest.mark.parametrize('chunk', [1, 8])
def test_the_lifter_on_cuda_gives_the_cpu_frames(chunk):
    from mocap_core.camera import CameraIntrinsics
    from mocap_lifter.online import OnlineLifter
    from mocap_lifter.weights import default_weights, load_weights

    intr = CameraIntrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
    kp = _keypoints()
    stamps = [33_333_333 * i for i in range(len(kp))]
    out = {}
    for device in ('cpu', 'cuda'):
        model = load_weights(default_weights('windowed'), device)
        online = OnlineLifter(model, 'windowed', device=device, chunk=chunk, flip=True,
                              output_sigma=2.0)
        frames = []
        for s, k in zip(stamps, kp):
            frames += online.push(s, k, intr)[0]
        frames += online.flush()
        assert [f.stamp_ns for f in frames] == stamps
        out[device] = np.stack([f.pose.joint_positions() for f in frames])
    err = np.abs(out['cpu'] - out['cuda']).max()
    print(f'chunk {chunk}: largest CPU/CUDA joint difference {1000 * err:.4f} mm')
    assert err < 1e-3                       # a millimetre: float32 rounding on both sides
