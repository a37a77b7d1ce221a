"""Gait analysis of the physics: strides, GRF curves, moments per kg (mocap eval gait)."""

from pathlib import Path

import numpy as np
import pytest

from mocap_physics.cycle_params import PhysicsParams
from mocap_physics.training.gait import (CYCLE_POINTS, analyse, heel_strikes, plot, run_gait,
                                         stride_curves)
from mocap_physics.training.evaluate import load_gt_bag

BAGS = Path(__file__).resolve().parents[3] / 'bags'


def test_heel_strikes_and_strides():
    c = np.zeros(100, dtype=bool)
    for start in (5, 35, 65, 95):
        c[start:start + 18] = True
    c[40] = False                       # a one-frame dropout is not a new strike
    strikes = heel_strikes(c)
    assert list(strikes) == [5, 35, 65, 95]
    values = np.arange(100, dtype=float)
    curves = stride_curves(values, strikes)
    assert curves.shape == (3, CYCLE_POINTS)
    np.testing.assert_allclose(curves[0, [0, -1]], [5, 35])
    # a stride longer than max_len (a missed strike) is skipped
    assert len(stride_curves(values, [0, 95], max_len=90)) == 0


@pytest.fixture(scope='module')
def walk():
    clip = load_gt_bag(BAGS / 'gt_cmu_walk_12_02')
    return analyse([run_gait(clip, PhysicsParams())])


def test_walking_forces_carry_the_body(walk):
    """The whole-body dynamics on a real walk: the feet carry about the body weight on
    average, with a loading peak above it, and the root residual stays small."""
    assert walk['strides'] >= 4
    assert 0.9 < walk['mean_total_vertical_grf_bw'] < 1.05
    assert walk['residual_root_over_weight_median'] < 0.1
    assert 1.0 < walk['peak_1_bw'] < 1.4
    assert 0.1 < walk['peak_1_at'] <= 0.3          # weight acceptance, not the strike spike
    curve = np.array(walk['grf_curve_bw'])
    assert 0.85 < curve[10:36].mean() < 1.25        # the loading response carries the body
    # the swing phase carries nothing
    assert curve[75:90].max() < 0.05
    ankle = walk['moments_per_kg']['ankle_sagittal']
    assert 0.3 < ankle['peak_positive'] < 2.5         # a plantarflexion moment at push-off


def test_plot_is_written(walk, tmp_path):
    path = tmp_path / 'gait.png'
    plot(walk, path)
    assert path.stat().st_size > 10000
