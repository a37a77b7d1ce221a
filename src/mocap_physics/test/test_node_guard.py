"""The physics node's callbacks are guarded: one that raises drops its frame, counts it on the
diagnostics and the node goes on (driven in process, as ``mocap process`` does)."""

import pytest


@pytest.fixture
def wired():
    import rclpy
    from rclpy.parameter import Parameter

    from mocap_core.inprocess import InProcessGraph
    from mocap_physics.node import PhysicsNode

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    outputs, errors = [], []
    graph = InProcessGraph(record=lambda topic, msg, qos: outputs.append(topic),
                           on_error=lambda node, topic, exc: errors.append((topic, exc)))
    node = PhysicsNode(context=context, parameter_overrides=[
        Parameter('floor_source', value='input')])
    graph.add(node)
    yield graph, node, outputs, errors
    node.destroy_node()
    context.try_shutdown()


def _motion(stamp_ns: int):
    from mocap_core.pose import Pose
    from mocap_core.ros_conversions import make_header, pose_to_motion
    from mocap_core.skeleton import Skeleton
    return pose_to_motion(Pose.rest(Skeleton.default()), make_header(stamp_ns, 'world'))


def test_every_callback_is_guarded(wired):
    _, node, _, _ = wired
    subs = [s for s in node.subscriptions if s.topic_name != '/parameter_events']
    assert {s.topic_name for s in subs} == {'/mocap/lifter/motion', '/mocap/lifter/contacts',
                                            '/mocap/lifter/bodies/motion',
                                            '/mocap/lifter/bodies/contacts'}
    assert all(getattr(s.callback, 'guarded', False) for s in subs)
    own_timers = [t for t in node.timers if t.callback != node.diag.publish]
    assert len(own_timers) == 1
    assert all(getattr(t.callback, 'guarded', False) for t in own_timers)
    assert node.diag._refresh and all(getattr(f, 'guarded', False) for f in node.diag._refresh)


def test_a_raising_callback_drops_the_frame_and_the_node_goes_on(wired, monkeypatch):
    from mocap_core import topics

    graph, node, outputs, errors = wired
    graph.publish(topics.LIFTER_MOTION, _motion(1_000_000_000))
    graph.flush()
    assert outputs.count(topics.PHYSICS_MOTION) == 1

    def broken(*args, **kwargs):
        raise RuntimeError('simulated failure')
    monkeypatch.setattr(node.online, 'add_motion', broken)
    before = (node.diag.errors, node.diag.dropped)
    graph.publish(topics.LIFTER_MOTION, _motion(1_033_333_333))
    assert errors == []
    assert (node.diag.errors, node.diag.dropped) == (before[0] + 1, before[1] + 1)
    values = {v.key: v.value for v in node.diag.status().values}
    assert 'simulated failure' in values['last_error']
    monkeypatch.undo()
    graph.publish(topics.LIFTER_MOTION, _motion(1_066_666_667))
    graph.flush()
    assert outputs.count(topics.PHYSICS_MOTION) == 2
