"""guarded(): a failing callback drops its frame, is counted in diagnostics and logged rate
limited; the callback's result and arguments pass through otherwise."""

from __future__ import annotations

import pytest

from mocap_core.guard import describe, guarded


class _Logger:
    def __init__(self):
        self.lines = []

    def error(self, text, throttle_duration_sec=None):
        self.lines.append((text, throttle_duration_sec))


class _Diag:
    def __init__(self):
        self.dropped = 0
        self.errors = 0
        self.values = {}

    def set_value(self, key, value):
        self.values[key] = value


class _Node:
    def __init__(self, diag=True):
        self.logger = _Logger()
        if diag:
            self.diag = _Diag()

    def get_logger(self):
        return self.logger


def test_failure_is_counted_logged_and_swallowed():
    node = _Node()
    seen = []

    def on_msg(msg):
        if msg < 0:
            raise ValueError(f'negative {msg}\nsecond line')
        seen.append(msg)
        return msg * 2

    cb = guarded(node, on_msg, 'keypoints')
    assert cb(3) == 6
    assert cb(-1) is None
    assert cb(-2) is None
    assert cb(4) == 8
    assert seen == [3, 4]
    assert node.diag.dropped == 2 and node.diag.errors == 2
    text, period = node.logger.lines[0]
    assert text == 'keypoints: frame dropped after an error (ValueError: negative -1 second line)'
    assert period and period > 0
    assert 'negative -2' in node.diag.values['last_error']


def test_node_without_diagnostics_and_default_name():
    node = _Node(diag=False)

    def on_timer():
        raise RuntimeError('x' * 500)

    guarded(node, on_timer)()
    text = node.logger.lines[0][0]
    assert text.startswith('on_timer: frame dropped after an error (RuntimeError: xxx')
    assert len(text) < 300


def test_keyboard_interrupt_is_not_swallowed():
    def stop():
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        guarded(_Node(), stop)()


def test_describe():
    assert describe(ValueError()) == 'ValueError'
    assert describe(KeyError('k')) == "KeyError: 'k'"


def test_keyed_rate_limit():
    from mocap_core.guard import KeyedRateLimit

    now = [0.0]
    limit = KeyedRateLimit(clock=lambda: now[0])
    assert limit.ready('a', 5.0) and limit.ready('b', 5.0)
    assert not limit.ready('a', 5.0)
    now[0] = 4.9
    assert not limit.ready('a', 5.0)
    now[0] = 5.0
    assert limit.ready('a', 5.0)
    assert not limit.ready('a', 5.0)



def test_deserialised_unless_decodes_only_what_is_used():
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from mocap_core.guard import deserialised_unless
    seen = []
    ignoring = [True]
    cb = deserialised_unless(lambda: ignoring[0], String, lambda m: seen.append(m.data))
    data = serialize_message(String(data='a'))
    assert cb(b'not CDR at all') is None and seen == []    # ignored: never decoded
    ignoring[0] = False
    cb(data)
    assert seen == ['a']
