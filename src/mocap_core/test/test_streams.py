"""StampOrder: increasing stamps pass, small steps back are stale, big jumps back restart."""

import pytest

from mocap_core.streams import StampOrder

S = 1_000_000_000


def test_increasing_stamps_are_accepted():
    order = StampOrder(1.0)
    assert [order.check(t * S // 30) for t in range(5)] == ['next'] * 5


def test_duplicate_and_small_step_back_are_stale():
    order = StampOrder(1.0)
    assert order.check(10 * S) == 'next'
    assert order.check(10 * S) == 'stale'
    assert order.check(10 * S - S // 2) == 'stale'
    assert order.stale == 2
    assert order.last_ns == 10 * S
    assert order.check(10 * S + 1) == 'next'


def test_jump_back_starts_a_new_stream_and_it_continues():
    order = StampOrder(1.0)
    for t in range(100):
        order.check(5 * S + t * S // 30)
    assert order.check(5 * S) == 'restart'
    assert order.restarts == 1
    assert order.check(5 * S + S // 30) == 'next'
    assert order.check(5 * S + S // 30) == 'stale'


def test_reset_and_bad_threshold():
    order = StampOrder(0.5)
    order.check(3 * S)
    order.reset()
    assert order.check(1) == 'next'
    with pytest.raises(ValueError):
        StampOrder(0.0)
