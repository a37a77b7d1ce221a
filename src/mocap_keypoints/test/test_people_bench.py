"""Helpers of ``mocap bench multipose`` (mocap_keypoints.people_bench)."""

from mocap_keypoints.people_bench import ping_pong, render


def test_ping_pong_plays_a_short_clip_back_and_forth_without_a_cut():
    assert ping_pong([0, 1, 2], 8) == [0, 1, 2, 1, 0, 1, 2, 1]
    assert ping_pong([0, 1, 2, 3], 3) == [0, 1, 2]
    assert ping_pong([7], 5) == [7] and ping_pong([], 5) == []
    seq = ping_pong(list(range(5)), 40)
    assert len(seq) == 40 and all(abs(a - b) == 1 for a, b in zip(seq, seq[1:]))


def test_report_has_both_ratios():
    r = {'frames': 10, 'size': '64x48', 'ids': {1: 9}, 'whole_frame_switches': 0}
    for name, med, mean in (('single', 10.0, 11.0), ('multi', 12.0, 16.5),
                            ('windows', 13.0, 17.0), ('coarse', 11.5, 15.0),
                            ('cycle', 12.5, 16.0)):
        r.update({f'{name}_ms': med, f'{name}_mean_ms': mean, f'{name}_found': {1: 10}})
    text = render({'clip': r}, 10)
    assert ('| clip | 10 | 64x48 | 10.0 | 12.0 | 13.0 | 11.5 | 12.5 | 11.0 | 16.5 | 17.0 | '
            '15.0 | 16.0 | 1.20 | 1.50 |') in text
    assert '| clip | 1: 10 | 1: 10 | 1: 10 | 1: 10 | 1: 10 | 1: 9 | 0 |' in text
    header = next(line for line in text.splitlines() if line.startswith('| clip | frames'))
    rule = text.splitlines()[text.splitlines().index(header) + 1]
    assert header.count('|') == rule.count('|')
