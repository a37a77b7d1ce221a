"""Starting the GMR node imports no training, dataset or plotting code (checked in a fresh
interpreter: import ``mocap_global.node``, construct ``GMRNode``, look at ``sys.modules``)."""

from __future__ import annotations

import json
import subprocess
import sys

FORBIDDEN = ('mocap_global.training', 'mocap_core.data.dataset', 'mocap_core.data.splits',
             'mocap_core.data.retarget', 'mocap_core.data.synth2d', 'mocap_core.data.bvh',
             'mocap_core.data.gt_bag', 'mocap_core.cli', 'tqdm', 'matplotlib')

# torch.hub imports tqdm when it is installed and falls back to a stub when the import fails,
# so the check refuses the forbidden imports (recording who asked) instead of only looking:
# torch's own optional import is allowed, any other attempt fails the test.
_PROBE = r'''
import importlib.abc, json, os, sys

FORBIDDEN = tuple(json.loads(sys.argv[1]))
attempts = []


def _forbidden(name):
    return any(name == f or name.startswith(f + '.') for f in FORBIDDEN)


class Refuse(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if not _forbidden(name):
            return None
        frame = sys._getframe(1)
        while frame is not None and (frame.f_code.co_filename.startswith('<frozen')
                                     or frame.f_code.co_filename == __file__):
            frame = frame.f_back
        attempts.append([name, frame.f_code.co_filename if frame else '?'])
        raise ModuleNotFoundError(f'refused by the test: {name}', name=name)


sys.meta_path.insert(0, Refuse())

import rclpy

from mocap_global.node import GMRNode

context = rclpy.Context()
rclpy.init(args=[], context=context)
node = GMRNode(context=context)
loaded = sorted(m for m in sys.modules if _forbidden(m))
node.destroy_node()
context.try_shutdown()
print(json.dumps({'loaded': loaded, 'attempts': attempts}))
'''


def test_starting_the_gmr_node_imports_no_training_code(tmp_path):
    probe = tmp_path / 'probe.py'
    probe.write_text(_PROBE)
    res = subprocess.run([sys.executable, str(probe), json.dumps(FORBIDDEN)],
                         capture_output=True, text=True, timeout=180)
    assert res.returncode == 0, res.stderr[-3000:]
    report = json.loads(res.stdout.strip().splitlines()[-1])
    assert report['loaded'] == []
    others = [(name, where) for name, where in report['attempts']
              if '/site-packages/torch/' not in where]
    assert others == [], others
