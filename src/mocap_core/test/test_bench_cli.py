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


def test_a_variant_must_name_its_node(tmp_path):
    for item, message in (('inference=torch', 'expected NODE.NAME=VALUE'),
                          ('planner.x=1', 'NODE: keypoints, lifter, physics, gmr')):
        out = subprocess.run([sys.executable, '-m', 'mocap_core.cli.mocap', 'bench',
                              'pipeline', '--variant', item, '--output',
                              str(tmp_path / 'report.md')],
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 2, out.stderr
        assert f"--variant '{item}'" in out.stderr and message in out.stderr
        assert 'offline' not in out.stdout and not (tmp_path / 'report.md').exists()


def test_the_report_gives_the_video_runs_side_by_side_as_a_ratio(tmp_path):
    from mocap_core.cli.bench import write_report

    res = {'date': '2026-11-28', 'commit': 'abc', 'machine': 'x86_64', 'live': [],
           'video_offline': {'video': 'v.mp4', 'frames': 96,
                             'fps': {'split': [10.0, 12.0, 11.0], 'one': [8.0, 10.0, 10.0]},
                             'fps_median': {'split': 11.0, 'one': 10.0},
                             'ratio_passes': [1.25, 1.2, 1.1], 'ratio_median': 1.2}}
    out = tmp_path / 'report.md'
    write_report(res, out)
    text = out.read_text()
    assert '## Offline from a video' in text and '`v.mp4` (96 frames), 3 pairs' in text
    assert '| detection beside the later stages (default) | 11.0 | 10.0, 12.0, 11.0 |' in text
    assert '| one frame after the other | 10.0 | 8.0, 10.0, 10.0 |' in text
    assert '**1.20x** (1.25, 1.20, 1.10)' in text
