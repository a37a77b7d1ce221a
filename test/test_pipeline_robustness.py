"""Robustness of the live pipeline: a node killed mid-stream and restarted; the others keep
running, the restarted node catches up, and the stages after it resume (each case leaves a
log line). The bag is played in a loop, so the stamps also jump back at every repetition."""

from __future__ import annotations

import signal
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GT_BAG = ROOT / 'bags' / 'gt_cmu_walk_12_02'


class _Counter:
    """Receive times and header stamps of /mocap/physics/motion and /mocap/world/motion, spun
    in a thread."""

    def __init__(self, domain_id: int) -> None:
        from trajectory_msgs.msg import MultiDOFJointTrajectory

        from mocap_core.ros_peer import RosPeer

        self.peer = RosPeer('robustness_counter', domain_id)
        self.times = {stage: self.peer.subscribe(
            MultiDOFJointTrajectory, f'/mocap/{stage}/motion',
            transform=lambda m: (time.monotonic(),
                                 m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec))
            for stage in ('physics', 'world')}
        self.peer.spin_in_background()

    def after(self, stage: str, t: float) -> int:
        return sum(1 for x, _ in list(self.times[stage]) if x > t)

    def stamps(self, stage: str, start: float, end: float) -> list:
        """Header stamps (s) of the messages received between ``start`` and ``end``."""
        return [s for x, s in list(self.times[stage]) if start < x <= end]

    def close(self) -> None:
        self.peer.close()


def test_physics_killed_and_restarted_mid_stream(processes, ros2_cmd, ros_env):
    counter = _Counter(int(ros_env['ROS_DOMAIN_ID']))
    try:
        lifter, lifter_log = processes.start([*ros2_cmd, 'run', 'mocap_lifter', 'lifter'],
                                             'lifter')
        physics, physics_log = processes.start([*ros2_cmd, 'run', 'mocap_physics', 'physics'],
                                               'physics')
        gmr, gmr_log = processes.start([*ros2_cmd, 'run', 'mocap_global', 'gmr'], 'gmr')
        processes.wait_for_text(lifter_log, 'lifter ready', 120, lifter)
        processes.wait_for_text(physics_log, 'physics on', 120, physics)
        processes.wait_for_text(gmr_log, 'gmr ready', 120, gmr)
        # no fixed delays: the counter's subscriptions have matched, and the player waits until
        # the lifter's inputs have matched before its first message (not again at each loop)
        assert counter.peer.wait_for_publishers(timeout=60), counter.peer.unmatched_subscriptions()
        player, play_log = processes.start(
            [*ros2_cmd, 'bag', 'play', str(GT_BAG), '--loop', '--wait-for-subscribers',
             '--wait-timeout', '60', '--topics', '/mocap/camera_info', '/mocap/keypoints2d'],
            'play')
        counter.peer.wait_until(lambda: counter.after('world', 0) >= 30, 60, proc=player)
        assert counter.after('world', 0) >= 30, (gmr_log.read_text(), play_log.read_text())

        physics.send_signal(signal.SIGKILL)                 # no clean shutdown
        physics.wait(10)
        killed = time.monotonic()
        time.sleep(1.5)
        assert counter.after('world', killed + 1.0) == 0    # nothing flows without physics
        physics2, physics2_log = processes.start(
            [*ros2_cmd, 'run', 'mocap_physics', 'physics'], 'physics_restarted')
        processes.wait_for_text(physics2_log, 'physics on', 120, physics2)
        restarted = time.monotonic()
        # (the counter may match the new node's publisher a moment after GMR does)
        counter.peer.wait_until(lambda: min(counter.after('physics', restarted),
                                            counter.after('world', restarted)) >= 60, 60)
        assert counter.after('physics', restarted) >= 60, physics2_log.read_text()
        assert counter.after('world', restarted) >= 60, gmr_log.read_text()
        assert player.poll() is None, play_log.read_text()
        player.send_signal(signal.SIGINT)
        player.wait(10)
        for proc, log in ((lifter, lifter_log), (gmr, gmr_log), (physics2, physics2_log)):
            text = log.read_text()
            assert proc.poll() is None, text
            assert 'Traceback' not in text, text
        # the loop makes the stamps jump back: the stages say so and go on
        assert 'jumped back' in lifter_log.read_text()
        # GMR saw its input stop and resume, and said so. Where in the looped bag the restarted
        # physics picks up decides how (it depends on how long the restart took): stamps after
        # a gap restart the accumulation, stamps more than max_gap_s back start a new stream
        # ('a bag restarted?'), stamps within max_gap_s before the last are dropped until they
        # advance (seen once under a CPU hog); stamps within max_gap_s after the last simply
        # continue the stream (seen once under load: the loop brought the bag back to where
        # it was), and there is nothing to say. Which of the first two GMR says depends on the
        # last stamp *it* received before the kill, which this counter (another subscriber,
        # which may miss the last messages of a killed publisher under load) cannot know:
        # once, under two busy processes, the counter's last stamp was the restarted node's
        # first while GMR had received later ones and restarted. So a discontinuity must be
        # reported, one way or the other.
        text = gmr_log.read_text()
        last = counter.stamps('physics', 0.0, killed)[-1]
        first = counter.stamps('physics', killed, float('inf'))[0]     # physics2's first
        max_gap = 0.25                                      # GMR's max_gap_s default
        if not last < first <= last + max_gap:
            assert 'restarted' in text or 'did not advance' in text, (last, first,
                                                                      text[-3000:])
    finally:
        counter.close()


def test_a_publisher_of_the_wrong_type_on_an_input_topic(processes, ros2_cmd, peer):
    """A std_msgs/String publisher on /mocap/keypoints2d next to the real keypoints: DDS does
    not match the types, the lifter lifts every real frame and stays up."""
    from std_msgs.msg import String
    from trajectory_msgs.msg import MultiDOFJointTrajectory

    # a deep input queue: every frame even when a loaded machine slows the node below the
    # bag's rate (the live default, 30, favours latency)
    lifter, log = processes.start([*ros2_cmd, 'run', 'mocap_lifter', 'lifter', '--ros-args',
                                   '-p', 'queue_depth:=1000'], 'lifter')
    processes.wait_for_text(log, 'lifter ready', 120, lifter)
    wrong = peer.publisher(String, '/mocap/keypoints2d', 10)
    got = peer.subscribe(MultiDOFJointTrajectory, '/mocap/lifter/motion')
    assert peer.wait_for_publishers(timeout=60, proc=lifter), log.read_text()
    player, play_log = processes.start(
        [*ros2_cmd, 'bag', 'play', str(GT_BAG), '--wait-for-subscribers', '--wait-timeout', '60',
         '--topics', '/mocap/camera_info', '/mocap/keypoints2d'], 'play')
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (player.poll() is None or len(got) < 168):
        wrong.publish(String(data='not keypoints'))
        peer.spin(0.02, step=0.02)
    assert player.returncode == 0, play_log.read_text()
    assert len(got) >= 160, len(got)            # best effort: a frame may be lost under load
    assert lifter.poll() is None and 'Traceback' not in log.read_text(), log.read_text()
