"""Starting the physics node: no training code imported; unusable DyNet weights end it with
exit status 2 and one line, without running anything a crafted file holds."""

import json
import os
import subprocess
import sys

import pytest
import torch

from mocap_core.checkpoint import WeightsError
from mocap_core.skeleton import Skeleton
from mocap_core.testing import crafted_weights, damaged_weights
from mocap_physics.cycle_params import PhysicsParams
from mocap_physics.dynet import DyNet, make_dynet
from mocap_physics.model import PhysicsModel

#: Modules a node must not load: training, datasets, progress bars, plotting.
FORBIDDEN_PREFIXES = ('mocap_physics.training', 'mocap_core.data.dataset',
                      'mocap_core.data.splits', 'mocap_core.data.retarget',
                      'mocap_core.data.synth2d', 'mocap_core.data.bvh', 'tqdm', 'matplotlib')

#: Builds PhysicsNode once per parameter set given as JSON in argv[1] and prints the forbidden
#: modules loaded and every attempt to import one. torch (learned gains) imports tqdm in
#: torch.hub when it is installed and does without it otherwise, so the probe refuses the
#: forbidden imports and records who asked instead of only looking at sys.modules.
PROBE = r'''
import importlib.abc
import json
import sys

PREFIXES = tuple(json.loads(sys.argv[2]))
attempts = []


def is_forbidden(name):
    return any(name == p or name.startswith(p + '.') for p in PREFIXES)


class Refuse(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if not is_forbidden(name):
            return None
        caller = sys._getframe(1)
        while caller is not None and caller.f_code.co_filename.startswith('<frozen'):
            caller = caller.f_back
        attempts.append([name, caller.f_code.co_filename if caller is not None else '?'])
        raise ModuleNotFoundError(f'refused by the test: {name}', name=name)


sys.meta_path.insert(0, Refuse())

import rclpy
from rclpy.parameter import Parameter

from mocap_physics.node import PhysicsNode

for overrides in json.loads(sys.argv[1]):
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    node = PhysicsNode(context=context, parameter_overrides=[
        Parameter(name, value=value) for name, value in overrides.items()])
    node.destroy_node()
    context.try_shutdown()
print(json.dumps({'modules': sorted(sys.modules),
                  'loaded': sorted(m for m in sys.modules if is_forbidden(m)),
                  'attempts': attempts}))
'''


def forbidden(modules):
    """The names in ``modules`` that a starting node must not have imported."""
    return sorted(m for m in modules
                  if any(m == p or m.startswith(p + '.') for p in FORBIDDEN_PREFIXES))


@pytest.fixture(scope='module')
def weights(tmp_path_factory):
    """An untrained DyNet weights file for the default skeleton."""
    path = tmp_path_factory.mktemp('dynet') / 'dynet.pt'
    make_dynet(PhysicsModel(Skeleton.default()), PhysicsParams(), hidden=16).save(path)
    return path


def test_forbidden_names_the_training_modules():
    assert forbidden(['mocap_physics.training', 'mocap_physics.training.evaluate',
                      'mocap_core.data.dataset', 'mocap_core.data.bvh', 'tqdm.auto',
                      'matplotlib', 'mocap_physics.node', 'mocap_core.data.motion',
                      'mocap_core.data.bvh_writer', 'tqdmx']) == [
        'matplotlib', 'mocap_core.data.bvh', 'mocap_core.data.dataset',
        'mocap_physics.training', 'mocap_physics.training.evaluate', 'tqdm.auto']


def test_starting_the_node_imports_no_training_code(weights):
    runs = [{}, {'gains_mode': 'learned', 'dynet_weights': str(weights)}]
    res = subprocess.run([sys.executable, '-c', PROBE, json.dumps(runs),
                          json.dumps(FORBIDDEN_PREFIXES)],
                         capture_output=True, text=True, timeout=180)
    assert res.returncode == 0, res.stderr
    report = json.loads(res.stdout.strip().splitlines()[-1])
    assert 'mocap_physics.node' in report['modules']           # the right process
    assert 'mocap_physics.dynet' in report['modules']          # learned gains were loaded
    assert report['loaded'] == [] and forbidden(report['modules']) == []
    # only torch's optional import of tqdm (torch.hub) may have asked
    others = [(name, where) for name, where in report['attempts']
              if f'{os.sep}torch{os.sep}' not in where]
    assert others == []


def _crafted(path, marker) -> None:
    crafted_weights(path, marker, key='config', state={})


def test_a_crafted_file_would_run_its_payload(tmp_path):
    """The crafted file below is a real threat: unpickled unsafely, it creates its marker."""
    marker = tmp_path / 'ran'
    _crafted(tmp_path / 'evil.pt', marker)
    torch.load(str(tmp_path / 'evil.pt'), weights_only=False)
    assert marker.exists()


def _bad_files(tmp_path, weights):
    damaged = damaged_weights(weights, tmp_path)
    truncated, rand = damaged['truncated'], damaged['random']
    crafted = tmp_path / 'crafted.pt'
    _crafted(crafted, tmp_path / 'pwned')
    wrong = tmp_path / 'wrong_size.pt'
    DyNet(20, 9, [1.0] * 9, [1.0] * 9, hidden=4).save(wrong)
    return {'truncated': truncated, 'random': rand, 'crafted': crafted, 'wrong_size': wrong}


def test_dynet_load_refuses_bad_files(tmp_path, weights):
    files = _bad_files(tmp_path, weights)
    for name in ('truncated', 'random', 'crafted'):
        with pytest.raises(WeightsError) as err:
            DyNet.load(files[name])
        assert str(files[name]) in str(err.value) and '\n' not in str(err.value)
    assert not (tmp_path / 'pwned').exists()
    net = DyNet.load(files['wrong_size'])
    with pytest.raises(WeightsError, match='do not fit the 18-joint skeleton'):
        net.check_fits(18, files['wrong_size'])
    torch.save({'config': {'in_size': 315, 'nv': 57, 'kp_ini': [1.0] * 57,
                           'kd_ini': [1.0] * 57, 'hidden': 8},
                'state': {'body.0.weight': torch.zeros(3, 3)}}, str(tmp_path / 'state.pt'))
    with pytest.raises(WeightsError, match='not DyNet weights'):
        DyNet.load(tmp_path / 'state.pt')
    torch.save({'config': {'layers': 3}, 'state': {}}, str(tmp_path / 'config.pt'))
    with pytest.raises(WeightsError, match='not DyNet weights'):
        DyNet.load(tmp_path / 'config.pt')
    assert DyNet.load(weights).config['hidden'] == 16


@pytest.mark.parametrize('case', ['truncated', 'random', 'crafted', 'wrong_size'])
def test_node_with_unusable_weights_exits_2_with_one_line(tmp_path, weights, case):
    path = _bad_files(tmp_path, weights)[case]
    res = subprocess.run([sys.executable, '-m', 'mocap_physics.node', '--ros-args',
                          '-p', 'gains_mode:=learned', '-p', f'dynet_weights:={path}'],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2, (res.stdout, res.stderr)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith('physics: error: ') and str(path) in lines[0], lines[0]
    assert 'Traceback' not in res.stderr + res.stdout
    assert not (tmp_path / 'pwned').exists()
