"""The world output's skating split by the camera-motion estimate (mocap_core.render.evaluate)."""

import numpy as np
import pytest


def test_world_skating_is_split_by_the_camera_state():
    """Each step between consecutive frames with the foot on the floor goes to its frames'
    camera-state group (a step across a change of state to its own group); frames off the
    floor count nowhere; a step over frames the output skipped (a live run's dropped frames)
    counts as that many rendered frames when the foot stood in all of them."""
    from mocap_core.render.evaluate import (CAMERA_STATE_GROUPS, camera_state_group,
                                            skating_by_camera_state)
    assert camera_state_group('static', True) == 'static'
    assert camera_state_group('rotating', True) == 'translation measured'
    assert camera_state_group('moving', False) == 'turning or moving, not measured'
    assert camera_state_group('unknown', True) == 'unknown'
    assert set(CAMERA_STATE_GROUPS) >= {'static', 'translation measured', 'state changes'}
    F = 6
    joints = np.zeros((F, 18, 3))
    for f in range(F):
        joints[f, :, 0] = 0.001 * f * (f + 1) / 2       # steps of 1, 2, 3, 4, 5 mm
    contacts = np.ones((F, 4), bool)
    contacts[5] = False                                 # the last step is off the floor
    groups = ['static', 'static', 'static', 'translation measured', 'translation measured',
              'translation measured']
    got = skating_by_camera_state(joints, np.arange(F), contacts, groups)
    assert got['static'] == pytest.approx([4 * (1 + 2), 8])
    assert got['state changes'] == pytest.approx([4 * 3, 4])
    assert got['translation measured'] == pytest.approx([4 * 4, 4])
    # a gap in the output frames: the step across it (1 -> 6 mm) spans two rendered frames
    got = skating_by_camera_state(joints[[0, 1, 3]], np.array([0, 1, 3]), contacts, groups)
    assert got == {'static': pytest.approx([4.0, 4]), 'state changes': pytest.approx([20.0, 8])}
    # ... unless the foot left the floor in a frame between
    contacts[2, 0] = False
    got = skating_by_camera_state(joints[[0, 1, 3]], np.array([0, 1, 3]), contacts, groups)
    assert got == {'static': pytest.approx([4.0, 4]), 'state changes': pytest.approx([15.0, 6])}
