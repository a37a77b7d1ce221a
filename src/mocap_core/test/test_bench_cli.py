"""`mocap bench pipeline`'s arguments and report, and `mocap bench camera-motion`'s scoring (the
benchmarks themselves are run by hand, not in tests)."""

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
                          ('gmr.inference', 'expected NODE.NAME=VALUE[,...]'),
                          ('planner.x=1', 'NODE: keypoints, lifter, physics, gmr'),
                          ('gmr.inferense=torch',
                           "the gmr node has no parameter 'inferense' (did you mean "
                           'inference')):
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


def test_camera_motion_bench_truth_settings_and_summary():
    import argparse

    import numpy as np
    import pytest

    from mocap_core.cli.bench_camera import parse_setting, summarise, true_states
    from mocap_core.rotations import axis_angle_to_matrix

    # a still camera, then a pan of 1 degree per frame, then a step of 5 cm
    R = np.stack([np.eye(3)] * 3 + [axis_angle_to_matrix(np.radians([0.0, k, 0.0]))
                                    for k in (1, 2, 2)])
    C = np.zeros((6, 3))
    C[5] = [0.05, 0, 0]
    assert true_states(R, C) == ['static', 'static', 'static', 'rotating', 'rotating', 'moving']
    assert parse_setting('15x2') == (15, 2)
    for bad in ('15', 'ax2', '1x2', '15x-1'):
        with pytest.raises(argparse.ArgumentTypeError):
            parse_setting(bad)

    def row(err, drift, cpu):
        return {'rotation_error_deg_s': err, 'drift_deg': drift, 'static_correct': 1.0,
                'states': {'static': 1.0, 'rotating': 0.0, 'moving': 0.0, 'unknown': 0.0},
                'cpu_ms': cpu}

    rows = [{'a': row(0.1, 1.0, 10.0), 'b': row(0.3, 2.0, 5.0)},
            {'a': row(0.2, 1.0, 10.0), 'b': row(None, 0.2, 5.0)}]
    s = summarise(rows, ['a', 'b'])
    assert s['b']['cpu_vs_reference'] == 0.5 and s['b']['rotation_error_deg_s'] == 0.3
    assert s['b']['drift_worse_better'] == (1, 1) and s['b']['error_worse_better'] == (1, 0)
    assert 'cpu_vs_reference' not in s['a']
