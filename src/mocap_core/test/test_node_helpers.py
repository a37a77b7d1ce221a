"""Metrics, diagnostics publishing and parameter declaration helpers."""

import math
import os

import pytest

from mocap_core.metrics import LatencyStats, RateMeter


def test_rate_meter_sliding_window():
    m = RateMeter(window_s=2.0, clock=lambda: 0.0)
    assert m.rate(0.0) == 0.0
    for i in range(21):
        m.tick(i * 0.1)           # 10 Hz for 2 s
    assert m.rate(2.0) == pytest.approx(10.0)
    assert m.total == 21
    assert m.rate(10.0) == 0.0    # all events left the window
    with pytest.raises(ValueError):
        RateMeter(window_s=0)


def test_latency_stats():
    s = LatencyStats(size=3)
    assert math.isnan(s.summary()['median'])
    for v in (5.0, 1.0, 2.0, 3.0):   # the oldest (5.0) falls out
        s.add(v)
    assert s.summary()['median'] == 2.0 and s.summary()['max'] == 3.0 and len(s) == 3


@pytest.fixture
def node():
    import rclpy
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '0')) % 200 + 30)
    n = rclpy.create_node('helpers_test', context=ctx)
    yield n
    n.destroy_node()
    rclpy.shutdown(context=ctx)


def test_diagnostics_status_fields_and_levels(node):
    from diagnostic_msgs.msg import DiagnosticStatus

    from mocap_core.diagnostics import NodeDiagnostics

    d = NodeDiagnostics(node, 'stage', hardware_id='cam0')
    for _ in range(3):
        d.input.tick()
        with d.processing():
            sum(range(1000))
        d.output.tick()
    d.dropped = 2
    d.set_value('model', 'motionet')
    st = d.status()
    values = {kv.key: kv.value for kv in st.values}
    assert st.level == DiagnosticStatus.OK and st.hardware_id == 'cam0'
    assert st.name == 'helpers_test: stage'
    assert values['frames_in'] == '3' and values['frames_dropped'] == '2'
    assert values['model'] == 'motionet' and float(values['processing_ms_median']) >= 0
    d.warn('no camera_info yet')
    assert d.status().level == DiagnosticStatus.WARN and d.status().message == 'no camera_info yet'
    d.error('solver failed')
    assert d.status().level == DiagnosticStatus.ERROR
    d.error(None)
    d.warn(None)
    assert d.status().level == DiagnosticStatus.OK
    d.publish()  # builds and publishes a DiagnosticArray without error


def test_diagnostics_report_matched_connections(node):
    """Watched endpoints report their matched counts: a publisher with its own node's
    subscription on the topic, an input without a publisher."""
    import time

    from std_msgs.msg import String

    from mocap_core.diagnostics import NodeDiagnostics
    from mocap_core.qos import STREAM_QOS

    d = NodeDiagnostics(node, 'stage')
    pub = node.create_publisher(String, '/helpers_test/out', STREAM_QOS)
    d.watch('out', pub)
    d.watch('in', node.create_subscription(String, '/helpers_test/in', lambda m: None,
                                           STREAM_QOS))
    values = {kv.key: kv.value for kv in d.status().values}
    assert values['publishers_in'] == '0' and values['subscribers_out'] == '0'
    node.create_subscription(String, '/helpers_test/out', lambda m: None, STREAM_QOS)
    deadline = time.monotonic() + 30
    while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert {kv.key: kv.value for kv in d.status().values}['subscribers_out'] == '1'
    node.destroy_publisher(pub)   # a destroyed endpoint is left out, not an error
    assert 'subscribers_out' not in {kv.key for kv in d.status().values}


def test_declare_parameters_with_descriptions_and_ranges(node):
    from rclpy.parameter import Parameter

    from mocap_core.parameters import ParamSpec, declare_parameters, describe_parameters

    specs = (ParamSpec('fps', 30.0, 'frames per second', min_value=1.0, max_value=120.0),
             ParamSpec('persons', 1, 'persons', min_value=1, max_value=4),
             ParamSpec('source', 'video', 'input kind', read_only=True))
    values = declare_parameters(node, specs)
    assert values == {'fps': 30.0, 'persons': 1, 'source': 'video'}
    desc = node.describe_parameter('fps')
    assert desc.description == 'frames per second'
    assert desc.floating_point_range[0].to_value == 120.0
    result = node.set_parameters([Parameter('fps', value=500.0)])[0]
    assert not result.successful
    assert node.describe_parameter('source').read_only
    table = describe_parameters(specs)
    assert '| `fps` | `30.0` | frames per second |' in table


def test_an_integer_for_a_float_parameter_is_taken_as_its_value():
    """``-p kp:=6400`` or ``--param physics.kp=6400`` on a float parameter: rclpy alone refuses
    the integer (the node would not start); declared through the specs it is 6400.0. A
    string for a float is still refused."""
    import rclpy
    from rclpy.exceptions import InvalidParameterTypeException
    from rclpy.parameter import Parameter

    from mocap_core.parameters import ParamSpec, declare_parameters

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get('ROS_DOMAIN_ID', '0')) % 200 + 30)
    try:
        specs = (ParamSpec('kp', 3600.0, 'gain'), ParamSpec('n', 6, 'count'))
        n = rclpy.create_node('int_for_float', context=ctx, parameter_overrides=[
            Parameter('kp', value=6400), Parameter('n', value=7)])
        values = declare_parameters(n, specs)
        assert values == {'kp': 6400.0, 'n': 7} and isinstance(values['kp'], float)
        n.destroy_node()
        plain = rclpy.create_node('int_for_float_plain', context=ctx,
                                  parameter_overrides=[Parameter('kp', value=6400)])
        with pytest.raises(InvalidParameterTypeException):
            plain.declare_parameter('kp', 3600.0)          # what rclpy does by itself
        plain.destroy_node()
        bad = rclpy.create_node('str_for_float', context=ctx,
                                parameter_overrides=[Parameter('kp', value='fast')])
        with pytest.raises(InvalidParameterTypeException):
            declare_parameters(bad, specs)
        bad.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


SPIN_SCRIPT = '''
import sys
import rclpy
from rclpy.node import Node
from mocap_core.parameters import spin_node

class Failing(Node):
    def __init__(self):
        super().__init__('failing')
        self.calls = 0
        self.diag = None
        self.create_timer(0.01, self.tick)

    def tick(self):
        self.calls += 1
        if self.calls <= 3:
            raise ValueError(f'bad frame {self.calls}')
        print(f'still running after {self.calls - 1} failures', flush=True)
        rclpy.shutdown()

sys.exit(spin_node(Failing, [], 'failing'))
'''


def test_spin_node_keeps_running_when_a_callback_raises(tmp_path):
    """A ValueError inside a running node's (unguarded) callback is logged and counted; the
    node keeps spinning and exits 0 at shutdown (it used to exit 2, 'configuration error')."""
    import subprocess
    import sys

    script = tmp_path / 'spin.py'
    script.write_text(SPIN_SCRIPT)
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert 'still running after 3 failures' in out.stdout
    assert 'frame dropped after an error (ValueError: bad frame 1)' in out.stderr
