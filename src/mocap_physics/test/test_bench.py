"""``mocap bench physics``: the configurations run side by side and report their times."""

import json

from mocap_physics import bench


def test_bench_runs_every_configuration_on_the_same_frames(capsys):
    assert bench.main(['--frames', '30', '--json']) == 0
    results = json.loads(capsys.readouterr().out)
    assert set(results) == set(bench.CONFIGS)
    for name, r in results.items():
        assert r['frames'] == 20                    # 30 minus the 10 warm-up frames
        assert 0 < r['ms_per_frame_median'] <= r['ms_per_frame_p95'] <= r['ms_per_frame_max']
        assert r['fallbacks'] == 0 and r['qp_failures'] == 0, name
    assert bench.main(['--frames', '20', '--configs', 'paper']) == 0
    text = capsys.readouterr().out
    assert 'paper' in text and 'whole_body ' not in text
