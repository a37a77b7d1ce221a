"""load_checkpoint: plain weights load; missing, damaged, crafted and non-dict files give one
WeightsError line and a crafted file never runs."""

from __future__ import annotations

import os
import pickle

import pytest
import torch

from mocap_core.checkpoint import WeightsError, load_checkpoint
from mocap_core.testing import CreatesFile


def test_plain_weights_load(tmp_path):
    path = tmp_path / 'w.pt'
    torch.save({'model': {'w': torch.ones(3)}, 'config': {'n': 3}}, path)
    state = load_checkpoint(path, required=('model', 'config'))
    assert torch.equal(state['model']['w'], torch.ones(3))


@pytest.mark.parametrize('case', ['missing', 'truncated', 'random', 'crafted', 'list', 'key'])
def test_bad_files_give_one_line(tmp_path, case):
    path = tmp_path / 'w.pt'
    marker = tmp_path / 'payload_ran'
    if case == 'truncated':
        torch.save({'model': {'w': torch.ones(1000)}}, path)
        path.write_bytes(path.read_bytes()[:200])
    elif case == 'random':
        path.write_bytes(os.urandom(4096))
    elif case == 'crafted':
        with path.open('wb') as f:
            pickle.dump({'model': CreatesFile(marker)}, f)
    elif case == 'list':
        torch.save([1, 2], path)
    elif case == 'key':
        torch.save({'model': {}}, path)
    with pytest.raises(WeightsError) as info:
        load_checkpoint(path, required=('model', 'config'))
    text = str(info.value)
    assert '\n' not in text and '\x1b' not in text and len(text) < 400
    assert str(path) in text
    assert not marker.exists()
    expected = {'missing': 'not found', 'truncated': 'not a readable weights file',
                'random': 'not a', 'crafted': 'refused',
                'list': 'expected a dictionary', 'key': 'missing config'}[case]
    assert expected in text
