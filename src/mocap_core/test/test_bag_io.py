"""Unit tests of mocap_core.bag_io and mocap_core.ros_msgs (no ROS graph involved)."""

from __future__ import annotations

import pytest
from mocap_core.bag_io import (
    BagError,
    BagReader,
    BagWriter,
    adapted_qos,
    message_definition,
    qos_to_dicts,
)
from mocap_core.ros_msgs import (
    MessageTypeError,
    deserialize,
    get_message_class,
    message_to_dict,
    message_to_yaml,
    msgtype_of,
    normalize_msgtype,
    ns_to_stamp,
    stamp_to_ns,
)


def _latched():
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _write_sample(path):
    """A bag with two topics; returns the (topic, stamp, bytes) written, in write order."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    written = []
    with BagWriter(path) as bag:
        bag.add_topic('/mocap/skeleton/urdf', 'std_msgs/msg/String', _latched())
        bag.add_topic('/joints', 'sensor_msgs/JointState')  # short spelling accepted
        urdf = String(data='<robot name="p"/>')
        bag.write_msg('/mocap/skeleton/urdf', 50, urdf)
        # write_msg stores CDR zero-padded to 4 bytes, as DDS delivers it
        padded = serialize_message(urdf) + bytes(-len(serialize_message(urdf)) % 4)
        assert len(padded) % 4 == 0 and padded != serialize_message(urdf)
        written.append(('/mocap/skeleton/urdf', 50, padded))
        for i in range(4):
            msg = JointState(name=['a', 'b'], position=[float(i), -0.5 * i])
            msg.header.stamp = ns_to_stamp(10 * i + 5)
            data = serialize_message(msg)
            # written out of time order on purpose: the reader must sort by time
            bag.write('/joints', 100 - 10 * i, data)
            written.append(('/joints', 100 - 10 * i, data))
    return written


def test_round_trip_is_byte_identical_and_time_ordered(tmp_path):
    path = tmp_path / 'bag'
    written = _write_sample(path)
    assert (path / 'metadata.yaml').is_file() and (path / 'bag.mcap').is_file()
    with BagReader(path) as bag:
        assert bag.message_count == 5
        assert bag.start_ns == 50 and bag.end_ns == 100 and bag.duration_ns == 50
        assert bag.storage_id == 'mcap' and not bag.warnings
        topics = bag.topics
        assert topics['/joints'].msgtype == 'sensor_msgs/msg/JointState'
        assert topics['/joints'].count == 4
        assert topics['/mocap/skeleton/urdf'].count == 1
        assert topics['/joints'].type_hash.startswith('RIHS01_')
        got = [(m.topic, m.timestamp_ns, m.data) for m in bag.messages()]
    assert got == sorted(written, key=lambda x: x[1])
    assert [m[1] for m in got] == sorted(m[1] for m in got)


def test_qos_is_kept(tmp_path):
    path = tmp_path / 'bag'
    _write_sample(path)
    with BagReader(path) as bag:
        qos = bag.topics['/mocap/skeleton/urdf'].qos
        assert qos is not None and len(qos) == 1
        assert qos[0].durability.name == 'TRANSIENT_LOCAL'
        assert qos[0].reliability.name == 'RELIABLE'
        assert qos_to_dicts(qos)[0]['durability'] == 'transient_local'
        assert bag.topics['/joints'].qos is None
        profile = adapted_qos(qos)
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
    assert profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert profile.reliability == ReliabilityPolicy.RELIABLE
    assert profile.depth >= 100
    assert adapted_qos(None).durability == DurabilityPolicy.VOLATILE


def test_copy_through_reader_and_writer_is_identical(tmp_path):
    _write_sample(tmp_path / 'a')
    with BagReader(tmp_path / 'a') as src, BagWriter(tmp_path / 'b') as dst:
        for info in src.topics.values():
            dst.add_topic(info.name, info.msgtype, info.qos, msgdef=info.msgdef,
                          type_hash=info.type_hash)
        for msg in src.messages():
            dst.write(msg.topic, msg.timestamp_ns, msg.data)
    with BagReader(tmp_path / 'a') as a, BagReader(tmp_path / 'b') as b:
        assert list(a.messages()) == list(b.messages())
        assert a.topics == b.topics


def test_single_mcap_file_is_readable(tmp_path):
    path = tmp_path / 'bag'
    written = _write_sample(path)
    lone = tmp_path / 'lone.mcap'
    lone.write_bytes((path / 'bag.mcap').read_bytes())
    with BagReader(lone) as bag:
        assert bag.message_count == 5
        assert bag.topics['/mocap/skeleton/urdf'].qos[0].durability.name == 'TRANSIENT_LOCAL'
        got = [(m.topic, m.timestamp_ns, m.data) for m in bag.messages(['/joints'])]
    assert got == sorted((w for w in written if w[0] == '/joints'), key=lambda x: x[1])


def test_truncated_mcap_keeps_complete_messages(tmp_path):
    path = tmp_path / 'bag'
    written = _write_sample(path)
    data = (path / 'bag.mcap').read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:-300])  # summary and footer lost, as when a recorder is killed
    with BagReader(cut) as bag:
        assert bag.warnings and 'damaged or incomplete' in bag.warnings[0]
        got = [(m.topic, m.timestamp_ns, m.data) for m in bag.messages()]
    assert got == sorted(written, key=lambda x: x[1])


def test_start_and_end_filters(tmp_path):
    path = tmp_path / 'bag'
    _write_sample(path)
    with BagReader(path) as bag:
        assert [m.timestamp_ns for m in bag.messages(start_ns=80)] == [80, 90, 100]
        assert [m.timestamp_ns for m in bag.messages('/joints', end_ns=80)] == [70]


@pytest.mark.parametrize('make, expected', [
    (lambda p: p / 'missing', "does not exist"),
    (lambda p: (p / 'x.mcap').write_bytes(b'not an mcap file at all') and p / 'x.mcap',
     'is not an MCAP file'),
    (lambda p: (p / 'x.mcap').write_bytes(b'') is not None and p / 'x.mcap', 'empty'),
    (lambda p: (p / 'notes.txt').write_text('hello') and p / 'notes.txt', 'is not a bag'),
    (lambda p: (p / 'd').mkdir() or p / 'd', 'no metadata.yaml and no .mcap'),
    (lambda p: ((p / 'd').mkdir(), (p / 'd' / 'metadata.yaml').write_text(': : [')) and p / 'd',
     'cannot read bag'),
])
def test_unreadable_inputs_raise_bag_error(tmp_path, make, expected):
    path = make(tmp_path)
    with pytest.raises(BagError) as err:
        BagReader(path)
    assert expected in str(err.value)
    assert '\n' not in str(err.value)


def test_unknown_topic_raises_bag_error(tmp_path):
    _write_sample(tmp_path / 'bag')
    with BagReader(tmp_path / 'bag') as bag:
        with pytest.raises(BagError, match=r"'/nope' not in bag .*\(it has: /joints"):
            bag.messages(['/joints', '/nope'])


def test_writer_errors(tmp_path):
    _write_sample(tmp_path / 'bag')
    with pytest.raises(BagError, match='already exists'):
        BagWriter(tmp_path / 'bag')
    keep = tmp_path / 'precious'
    keep.mkdir()
    (keep / 'thesis.tex').write_text('x')
    with pytest.raises(BagError, match='refusing'):
        BagWriter(keep, overwrite=True)
    assert (keep / 'thesis.tex').exists()
    with BagWriter(tmp_path / 'bag', overwrite=True) as bag:
        with pytest.raises(BagError, match='not added'):
            bag.write('/x', 1, b'\x00\x01\x00\x00')
        with pytest.raises(BagError, match='no message definition'):
            bag.add_topic('/x', 'no_such_pkg/msg/Thing')
        with pytest.raises(BagError, match='invalid message type'):
            bag.add_topic('/x', 'not a type')
        bag.add_topic('/x', 'std_msgs/msg/String')
        with pytest.raises(BagError, match='was added as'):
            bag.add_topic('/x', 'std_msgs/msg/Int32')
        with pytest.raises(BagError, match='absolute'):
            bag.add_topic('relative', 'std_msgs/msg/String')
    with BagReader(tmp_path / 'bag') as bag:  # overwritten: the old content is gone
        assert bag.message_count == 0 and list(bag.topics) == ['/x']


def test_message_definition_of_standard_types():
    msgdef, rihs = message_definition('sensor_msgs/Image')
    assert msgdef.startswith('std_msgs/Header header') and rihs.startswith('RIHS01_')


def test_message_type_helpers():
    from sensor_msgs.msg import Image
    assert normalize_msgtype('sensor_msgs/Image') == 'sensor_msgs/msg/Image'
    assert normalize_msgtype('sensor_msgs.msg.Image') == 'sensor_msgs/msg/Image'
    assert get_message_class('sensor_msgs/msg/Image') is Image
    assert get_message_class('sensor_msgs/Image') is Image
    assert msgtype_of(Image()) == 'sensor_msgs/msg/Image'
    with pytest.raises(MessageTypeError, match="package 'no_pkg' is not installed"):
        get_message_class('no_pkg/msg/X')
    with pytest.raises(MessageTypeError, match="no msg named 'NoSuch'"):
        get_message_class('std_msgs/msg/NoSuch')
    assert stamp_to_ns(ns_to_stamp(1_700_000_000_123_456_789)) == 1_700_000_000_123_456_789


def test_message_to_yaml_like_topic_echo():
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import CameraInfo, Image

    info = CameraInfo(width=640, distortion_model='plumb_bob', d=[0.1, 0.2])
    info.header.frame_id = 'cam'
    info = deserialize(serialize_message(info), 'sensor_msgs/msg/CameraInfo')
    text = message_to_yaml(info)
    assert text.startswith('header:\n  stamp:\n    sec: 0\n    nanosec: 0\n  frame_id: cam\n')
    assert 'distortion_model: plumb_bob\nd:\n- 0.1\n- 0.2\nk:\n- 0.0\n' in text
    assert 'roi:\n  x_offset: 0\n' in text
    short = message_to_yaml(info, no_arr=True)
    assert "d: '<sequence type: double, length: 2>'" in short
    assert "k: '<array type: double[9]>'" in short
    image = Image(data=bytes(range(10)))
    assert message_to_dict(image, truncate_length=3)['data'] == [0, 1, 2, '...']
    status = DiagnosticStatus(level=DiagnosticStatus.WARN, values=[KeyValue(key='k', value='v')])
    assert message_to_dict(status)['level'] == 1
    assert message_to_dict(status)['values'] == [{'key': 'k', 'value': 'v'}]
    with pytest.raises(ValueError, match='cannot deserialise'):
        deserialize(b'\x00\x01\x00\x00\xff', 'sensor_msgs/msg/CameraInfo')
