"""Corrupt and crafted weight files: loading never runs code from the file, and the node and
``mocap eval gmr`` end with one line ``...: error: ...`` and exit status 2, no traceback."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import List, Tuple

import pytest
import torch

from mocap_core.checkpoint import WeightsError
from mocap_core.testing import crafted_weights, damaged_weights

from mocap_global.model import GMR, GMRConfig
from mocap_global.weights import load_weights, read_info, save_weights


def _bad_files(tmp_path: Path) -> Tuple[List[Tuple[str, Path]], Path]:
    """(name, file) of a truncated weights file, random bytes and a crafted pickle; and the
    file the crafted pickle would create."""
    good = tmp_path / 'good.pt'
    save_weights(GMR(GMRConfig(layers=1, hidden=8, projection=8)), good, {'note': 'test'})
    damaged = damaged_weights(good, tmp_path)
    marker = tmp_path / 'pwned'
    crafted = crafted_weights(tmp_path / 'crafted.pt', marker, config={}, info={})
    return [('truncated', damaged['truncated']), ('random bytes', damaged['random']),
            ('crafted', crafted)], marker


def test_load_weights_refuses_bad_files_without_running_them(tmp_path):
    files, marker = _bad_files(tmp_path)
    for name, path in files:
        with pytest.raises(WeightsError) as err:
            load_weights(path)
        assert str(path) in str(err.value) and '\n' not in str(err.value), name
    assert not marker.exists()
    # a well-formed file that is not GMR weights (another network's configuration)
    other = tmp_path / 'other.pt'
    torch.save({'model': {}, 'config': {'kernel': 3}, 'info': {}}, other)
    with pytest.raises(WeightsError, match='not GMR weights'):
        load_weights(other)
    assert read_info(tmp_path / 'good.pt') == {'note': 'test'}


def _one_line_error(res: subprocess.CompletedProcess, prefix: str) -> None:
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 2, (res.returncode, res.stderr[-2000:])
    assert len(lines) == 1 and lines[0].startswith(prefix), res.stderr[-2000:]
    assert 'Traceback' not in res.stderr + res.stdout


def _run_all(cmds: List[List[str]]) -> List[subprocess.CompletedProcess]:
    """Run the commands side by side (each loads torch: seconds)."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    procs = [subprocess.Popen(c, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env=env, stdin=subprocess.DEVNULL) for c in cmds]
    out = []
    for c, p in zip(cmds, procs):
        stdout, stderr = p.communicate(timeout=180)
        out.append(subprocess.CompletedProcess(c, p.returncode, stdout, stderr))
    return out


def test_gmr_node_exits_with_one_line_for_bad_weights(tmp_path):
    """``ros2 run mocap_global gmr --ros-args -p weights:=bad.pt``."""
    files, marker = _bad_files(tmp_path)
    cmds = [[sys.executable, '-m', 'mocap_core.cli.ros2', 'run', 'mocap_global', 'gmr',
             '--ros-args', '-p', f'weights:={path}'] for _, path in files]
    for (name, path), res in zip(files, _run_all(cmds)):
        _one_line_error(res, 'gmr: error: ')
        assert str(path) in res.stderr, name
    assert not marker.exists()


def test_mocap_eval_gmr_exits_with_one_line_for_bad_weights(tmp_path):
    """``mocap eval gmr --weights bad.pt`` (before any dataset is read)."""
    files, marker = _bad_files(tmp_path)
    cmds = [[sys.executable, '-m', 'mocap_core.cli.mocap', 'eval', 'gmr', '--weights',
             str(path), '--no-bags', '--max-clips', '1', '--out', str(tmp_path / 'report')]
            for _, path in files]
    for (name, path), res in zip(files, _run_all(cmds)):
        _one_line_error(res, 'mocap eval gmr: error: ')
        assert str(path) in res.stderr, name
    assert not marker.exists()
    assert not (tmp_path / 'report').exists()
