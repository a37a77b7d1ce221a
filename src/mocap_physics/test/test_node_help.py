"""The node's --help prints the parameter table and exits 0 (no ROS graph needed)."""

import subprocess
import sys

from mocap_physics.node import PARAMETERS


def test_help_prints_parameter_table():
    out = subprocess.run([sys.executable, '-m', 'mocap_physics.node', '--help'],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert 'ros2 run mocap_physics physics' in out.stdout
    assert '| parameter | default | description |' in out.stdout
    for spec in PARAMETERS:
        assert f'| `{spec.name}` |' in out.stdout
