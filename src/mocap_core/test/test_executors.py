"""The process's rclpy executor (mocap_core.executors) and the spin loop of every node."""

import signal
import subprocess
import time
import sys

import pytest

from mocap_core.executors import (DEFAULT, SHUTDOWN_HANG, executor_kind, make_executor,
                                  spin_until)


def test_executor_kind_reads_the_environment_and_falls_back(monkeypatch, capsys):
    monkeypatch.delenv('MOCAP_EXECUTOR', raising=False)
    assert executor_kind() == DEFAULT == 'events'
    monkeypatch.setenv('MOCAP_EXECUTOR', 'Single-Threaded')
    assert executor_kind() == 'single_threaded'
    monkeypatch.setenv('MOCAP_EXECUTOR', '')
    assert executor_kind() == 'events'
    assert capsys.readouterr().err == ''
    monkeypatch.setenv('MOCAP_EXECUTOR', 'multi')
    assert executor_kind() == 'single_threaded'
    assert "MOCAP_EXECUTOR='multi'" in capsys.readouterr().err
    assert executor_kind('events') == 'events'          # an explicit value wins


@pytest.fixture
def context():
    import rclpy
    from rclpy.context import Context

    ctx = Context()
    rclpy.init(context=ctx)
    yield ctx
    ctx.try_shutdown()


def test_make_executor_kinds(context):
    from rclpy.executors import SingleThreadedExecutor

    events = make_executor('events', context=context)
    assert not isinstance(events, SingleThreadedExecutor)
    assert type(events).__name__ == 'EventsExecutor'
    assert isinstance(make_executor('single_threaded', context=context),
                      SingleThreadedExecutor)


@pytest.mark.parametrize('kind', ['events', 'single_threaded'])
def test_spin_until_delivers_and_hands_on_errors(context, kind):
    """Messages published by a timer reach a subscription through either executor; an
    exception that escapes a callback goes to on_error and spinning goes on until the
    condition says stop."""
    import rclpy
    from std_msgs.msg import Int32

    node = rclpy.create_node('spin_until_test', context=context)
    got, errors = [], []
    pub = node.create_publisher(Int32, 'numbers', 10)

    def on_number(msg):
        got.append(msg.data)
        if msg.data == 2:
            raise ValueError('bad frame')

    node.create_subscription(Int32, 'numbers', on_number, 10)
    count = iter(range(1000))
    node.create_timer(0.01, lambda: pub.publish(Int32(data=next(count))))
    executor = make_executor(kind, context=context)
    executor.add_node(node)
    try:
        spin_until(executor, lambda: len(got) < 6 and len(errors) < 50, errors.append)
    finally:
        executor.remove_node(node)
        node.destroy_node()
    assert got[:6] == [0, 1, 2, 3, 4, 5]
    assert len(errors) == 1 and isinstance(errors[0], ValueError)
    with pytest.raises(ValueError):       # without on_error it is raised
        spin_until(_Raising(), lambda: True)


class _Raising:
    def spin_once(self, timeout_sec=None):
        raise ValueError('escaped')


IDLE_NODE_SCRIPT = '''
import sys
import rclpy
from rclpy.node import Node
from mocap_core.parameters import spin_node

class Idle(Node):
    def __init__(self):
        super().__init__('idle')
        self.diag = None
        self.declare_parameter('gain', 2.5)
        self.once = self.create_timer(0.05, self.tick)

    def tick(self):
        self.once.cancel()
        print('spinning', flush=True)

sys.exit(spin_node(Idle, [], 'idle'))
'''


@pytest.mark.parametrize('kind', ['events', 'single_threaded'])
def test_a_node_process_stops_on_sigint_with_either_executor(tmp_path, kind):
    """``ros2 run`` nodes (spin_node) end with status 0 on Ctrl-C. (The events executor's own
    ``spin()`` would not sleep at all; the loop is spin_once with a timeout.)"""
    import os

    script = tmp_path / 'idle.py'
    script.write_text(IDLE_NODE_SCRIPT)
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            env={**os.environ, 'MOCAP_EXECUTOR': kind})
    try:
        assert proc.stdout.readline().strip() == 'spinning'     # blocks until it spins
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert 'Traceback' not in err, err
    assert SHUTDOWN_HANG not in err, err          # the teardown ended by itself


@pytest.mark.parametrize('kind', ['events', 'single_threaded'])
def test_a_node_process_answers_parameter_requests_with_either_executor(tmp_path, kind):
    """`ros2 param get` works on a node spun by spin_node (its parameter services are served
    by the executor like any other entity)."""
    import os
    import random

    import rclpy
    from rclpy.context import Context
    from rclpy.parameter_client import AsyncParameterClient

    domain = str(random.randint(1, 200))
    script = tmp_path / 'idle.py'
    script.write_text(IDLE_NODE_SCRIPT)
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            env={**os.environ, 'MOCAP_EXECUTOR': kind, 'ROS_DOMAIN_ID': domain,
                                 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'})
    ctx = Context()
    rclpy.init(context=ctx, domain_id=int(domain))
    try:
        node = rclpy.create_node('param_client', context=ctx)
        client = AsyncParameterClient(node, 'idle')
        assert client.wait_for_services(timeout_sec=60)
        executor = make_executor('single_threaded', context=ctx)
        executor.add_node(node)
        # The service being discovered does not mean the reply path is matched yet (DDS matches
        # the request and the reply topics separately), so a first request can go unanswered on
        # a busy machine, as `ros2 param get` would then time out. Ask again until answered.
        deadline = time.monotonic() + 60
        while True:
            future = client.get_parameters(['gain'])
            executor.spin_until_future_complete(future, timeout_sec=5)
            if future.done() or time.monotonic() > deadline:
                break
        assert future.done() and future.result().values[0].double_value == 2.5
        node.destroy_node()
    finally:
        ctx.try_shutdown()
        proc.send_signal(signal.SIGINT)
        try:
            proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
    assert proc.returncode == 0


TEARDOWN_SCRIPT = '''
import sys, time
from mocap_core.executors import close_nodes, init_rclpy
import rclpy

hang, limit, hard = float(sys.argv[1]), float(sys.argv[2]), sys.argv[3] == 'hard'
signals = init_rclpy([])
order = []

class Executor:
    def remove_node(self, node):
        order.append('remove_node')

    def shutdown(self, timeout_sec=None):
        order.append('shutdown')
        print('tearing down', flush=True)
        time.sleep(hang)

class Node:
    def destroy_node(self):
        order.append('destroy_node')

ok = close_nodes(Executor(), [Node(), None], before=[lambda: order.append('before')],
                 limit_s=limit, label='teardown', hard_exit=hard)
print('closed', order, ok, rclpy.ok(), flush=True)
'''


@pytest.mark.parametrize('hang_s, limit_s, mode', [(0.0, 30.0, 'hard'), (120.0, 1.0, 'hard'),
                                                   (3.0, 1.0, 'soft')])
def test_close_nodes_tears_down_in_order_and_never_hangs(tmp_path, hang_s, limit_s, mode):
    """The ordered teardown of a node process; a step that hangs has every thread's stack
    printed on stderr after ``limit_s``: a node process (hard) then exits with status 0, a
    library call (soft) goes on and reports it."""
    from mocap_core.executors import SHUTDOWN_HANG

    script = tmp_path / 'teardown.py'
    script.write_text(TEARDOWN_SCRIPT)
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, str(script), str(hang_s), str(limit_s), mode],
                          capture_output=True, text=True, timeout=90)
    assert proc.returncode == 0, proc.stderr
    order = "['before', 'remove_node', 'shutdown', 'destroy_node']"
    if hang_s == 0:
        assert f'closed {order} True False' in proc.stdout, proc.stdout + proc.stderr
        assert SHUTDOWN_HANG not in proc.stderr
        return
    assert f'{SHUTDOWN_HANG} 1 s' in proc.stderr, proc.stderr
    assert 'in shutdown' in proc.stderr                  # the stack of the hanging step
    if mode == 'hard':
        assert 'tearing down' in proc.stdout and 'closed' not in proc.stdout
        assert time.monotonic() - t0 < 60
    else:
        assert f'closed {order} False False' in proc.stdout, proc.stdout + proc.stderr


SIGNAL_SCRIPT = '''
import os, signal, sys
from mocap_core.executors import StopSignals

before = signal.getsignal(signal.SIGINT)
stop = StopSignals().install()
os.kill(os.getpid(), signal.SIGINT)
os.kill(os.getpid(), signal.SIGTERM)
print('requested', stop.requested, stop.count, flush=True)
try:
    os.kill(os.getpid(), signal.SIGINT)
except KeyboardInterrupt:
    print('third gives up', flush=True)
stop.restore()
print('restored', signal.getsignal(signal.SIGINT) is before, flush=True)
'''


def test_stop_signals_request_a_stop_and_the_third_gives_up(tmp_path):
    """SIGINT / SIGTERM set ``requested`` instead of raising inside the executor; the third
    signal raises KeyboardInterrupt; ``restore`` puts Python's handler back."""
    script = tmp_path / 'signals.py'
    script.write_text(SIGNAL_SCRIPT)
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split('\n')[:3] == ['requested True 2', 'third gives up',
                                           'restored True'], proc.stdout
