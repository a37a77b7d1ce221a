"""The opt-in MotioNet weights shipped beside the default (``motionet_windowed_rendered_v6.pt``,
``motionet_windowed_strict.pt``; figures in src/mocap_lifter/weights/README.md) load, lift the
committed validation bags (clips none of them trained on) with test-time flip to the accuracy
they were shipped with (a regression bound: a broken file, feature or flip path fails it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from test.test_vtm_shipped import BAGS, _ground_truth

ROOT = Path(__file__).resolve().parents[1]
WEIGHTS = ROOT / 'src' / 'mocap_lifter' / 'weights'
# MPJPE (mm) measured with `mocap process` and flip on, 2026-11-23 (weights/README.md), plus
# 15 %: the whole-sequence pass here differs a little from the streamed one
SHIPPED_MM = {
    # stage 8, the default from session 39 to 58: this test's whole-sequence pass, 2026-11-30
    'motionet_windowed_rendered_v6.pt': {'gt_cmu_walk_12_02': 54.8,
                                         'gt_bandai_walk_exhausted': 38.3,
                                         'gt_bandai_wave_normal': 64.4},
    'motionet_windowed_strict.pt': {'gt_cmu_walk_12_02': 67.7,
                                    'gt_bandai_walk_exhausted': 40.2,
                                    'gt_bandai_wave_normal': 51.1},
}


@pytest.fixture(scope='module', params=sorted(SHIPPED_MM))
def weights(request):
    from mocap_lifter.weights import load_weights
    torch.set_num_threads(1)
    return request.param, load_weights(WEIGHTS / request.param)


@pytest.mark.parametrize('bag', BAGS)
def test_optin_weights_lift_the_validation_bags(weights, bag):
    from mocap_lifter.features import lifter_features
    from mocap_lifter.training.evaluate import lift
    from mocap_lifter.training.metrics import mpjpe_mm

    name, model = weights
    kp, intr, poses = _ground_truth(bag)
    gt = np.stack([p.joint_positions() for p in poses])
    feats, root_2d, scale, _ = lifter_features(kp, intr)
    with torch.no_grad():
        out = lift(model.eval(), feats, root_2d.astype(np.float32), scale.astype(np.float32),
                   flip=True)
    err = mpjpe_mm(out['positions'].astype(np.float64), gt)
    print(f'{name} {bag}: MPJPE {err:.1f} mm')
    assert err < 1.15 * SHIPPED_MM[name][bag]
