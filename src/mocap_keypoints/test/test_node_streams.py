"""The keypoint node with ``source:=topic`` (built in-process, images delivered through its
subscription by InProcessGraph): a stream whose stamps jump back (a looped bag, a restarted
driver) restarts instead of being dropped as stale for ever; a small step back is still
dropped as stale; a failing callback drops only its frame."""

from __future__ import annotations

import numpy as np
import pytest

S = 1_000_000_000
T0 = 1_700_000_000 * S


@pytest.fixture
def topic_node():
    import rclpy
    from rclpy.parameter import Parameter

    from mocap_core.inprocess import InProcessGraph
    from mocap_keypoints.node import KeypointsNode

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    out = []
    graph = InProcessGraph(record=lambda topic, msg, qos: out.append((topic, msg)))
    node = graph.add(KeypointsNode(context=context, parameter_overrides=[
        Parameter('source', value='topic'), Parameter('synchronous', value=True)]))
    yield graph, node, out
    node.shutdown()
    node.destroy_node()
    context.try_shutdown()


def _image(stamp_ns: int):
    from mocap_core.ros_conversions import bgr_to_image, make_header

    return bgr_to_image(np.full((240, 320, 3), 90, np.uint8), make_header(stamp_ns, 'cam'))


def _stamps(out, topic='/mocap/keypoints2d'):
    from mocap_core.ros_conversions import stamp_to_ns

    return [stamp_to_ns(m.header.stamp) for t, m in out if t == topic]


def test_stamps_jumping_back_start_a_new_stream(topic_node):
    graph, node, out = topic_node
    first = [T0 + i * S // 30 for i in range(10)]
    second = [T0 - 5 * S + i * S // 30 for i in range(10)]    # the bag played again
    for stamp in first + second:
        graph.publish('/camera/image_raw', _image(stamp))
    assert _stamps(out) == first + second
    assert node.diag.dropped == 0


def test_small_step_back_is_stale(topic_node):
    graph, node, out = topic_node
    stamps = [T0, T0 + S // 30, T0 + S // 60, T0 + 2 * S // 30]
    for stamp in stamps:
        graph.publish('/camera/image_raw', _image(stamp))
    assert _stamps(out) == [stamps[0], stamps[1], stamps[3]]
    assert node.diag.dropped == 1


def test_a_failing_callback_drops_only_its_frame(topic_node):
    """An exception inside the image callback (here: publishing fails once) drops that frame,
    is counted, and the next frames go through."""
    graph, node, out = topic_node
    real = node.pub_info.publish
    calls = {'n': 0}

    def flaky(msg):
        calls['n'] += 1
        if calls['n'] == 2:
            raise ValueError('boom')
        return real(msg)

    node.pub_info.publish = flaky
    stamps = [T0 + i * S // 30 for i in range(4)]
    for stamp in stamps:
        graph.publish('/camera/image_raw', _image(stamp))
    assert _stamps(out) == [stamps[0]] + stamps[2:]
    assert node.diag.errors == 1
    assert node.diag.dropped == 1


def test_opencv_threads_sets_the_process_pool_and_zero_leaves_it():
    """``opencv_threads`` (default 1) is OpenCV's pool while the node runs, restored at
    shutdown; 0 leaves OpenCV's setting alone."""
    import cv2
    import rclpy
    from rclpy.parameter import Parameter

    from mocap_keypoints.node import KeypointsNode

    before = cv2.getNumThreads()
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    try:
        cv2.setNumThreads(2)
        for value, running in ((None, 1), (3, 3), (0, 2)):
            overrides = [Parameter('source', value='topic')]
            if value is not None:
                overrides.append(Parameter('opencv_threads', value=value))
            node = KeypointsNode(context=context, parameter_overrides=overrides)
            try:
                assert cv2.getNumThreads() == running
            finally:
                node.shutdown()
                node.destroy_node()
            assert cv2.getNumThreads() == 2
    finally:
        context.try_shutdown()
        cv2.setNumThreads(before)
