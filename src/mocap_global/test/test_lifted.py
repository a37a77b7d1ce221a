"""GMR inputs as the lifter gives them (mocap_global.training.lifted) and the ``lifted``
evaluation input."""

from pathlib import Path

import numpy as np

from mocap_core.rotations import quat_to_matrix
from mocap_core.testing import groundtruth_motion

BAGS = Path(__file__).resolve().parents[3] / 'bags'


def _angle_deg(a, b):
    r = np.einsum('...ji,...jk->...ik', quat_to_matrix(a), quat_to_matrix(b))
    return np.degrees(np.arccos(np.clip((np.trace(r, axis1=-2, axis2=-1) - 1) / 2, -1, 1)))


def test_lifted_clips_are_frame_aligned_cached_and_the_lifters_view(tmp_path):
    from mocap_global.training.evaluate import LIFTED, clip_arrays
    from mocap_global.training.lifted import lift_clips

    m = groundtruth_motion(BAGS / 'gt_cmu_walk_12_02')
    m.name = 'gt_cmu_walk_12_02'
    clips = lift_clips([m], cameras=2, seed=5, cache_dir=tmp_path, progress=False)
    c = clips[0]
    assert c.rotations.shape == (2, m.num_frames, 18, 4) and c.lengths.shape == (2, 10)
    assert len(list(tmp_path.glob('*.npz'))) == 1
    again = lift_clips([m], cameras=2, seed=5, cache_dir=tmp_path, progress=False)[0]
    np.testing.assert_array_equal(again.rotations, c.rotations)         # from the cache
    # the lifter's local rotations: near the truth on this walk, but not the truth, and the
    # two cameras see it differently
    err = _angle_deg(c.rotations[:, :, 1:], m.rotations[None, :, 1:]).mean()
    assert 3.0 < err < 45.0, err
    assert not np.allclose(c.rotations[0], c.rotations[1])
    assert np.all(np.abs(c.lengths / m.skeleton.group_lengths() - 1) < 0.5)
    # the evaluation input 'lifted' is those poses
    LIFTED[m.name] = c
    try:
        a = clip_arrays(m, 30.0, 'lifted', pose_input='positions')
        b = clip_arrays(m, 30.0, 'none', pose_input='positions')
        assert a['features'].shape == b['features'].shape
        assert not np.allclose(a['features'], b['features'])
        np.testing.assert_array_equal(a['dT'], b['dT'])        # the targets stay the truth
    finally:
        LIFTED.pop(m.name, None)
