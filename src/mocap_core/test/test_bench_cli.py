"""`mocap bench pipeline`'s arguments (the benchmark itself is run by hand, not in tests)."""

import subprocess
import sys


def test_a_malformed_keypoints_variant_is_one_error_line_before_any_run(tmp_path):
    out = subprocess.run([sys.executable, '-m', 'mocap_core.cli.mocap', 'bench', 'pipeline',
                          '--keypoints-variant', 'mirror_check', '--output',
                          str(tmp_path / 'report.md')],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    assert "--keypoints-variant 'mirror_check': expected NAME=VALUE" in out.stderr
    assert 'offline' not in out.stdout and not (tmp_path / 'report.md').exists()
