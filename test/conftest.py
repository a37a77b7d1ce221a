"""Shared fixtures of the integration tests: an isolated ROS environment for subprocesses,
their processes, and an rclpy peer in the test process.

Every test session picks its own random ``ROS_DOMAIN_ID`` and keeps discovery on this machine
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``), so parallel runs and other ROS programs on the
network do not see each other's topics.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

_DOMAIN_ID = random.SystemRandom().randint(1, 200)


@pytest.fixture(scope='session')
def ros_env() -> dict[str, str]:
    """Environment for ROS subprocesses: ``os.environ`` plus isolation and strictness settings."""
    env = dict(os.environ)
    env.update({
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
        'ROS_DOMAIN_ID': str(_DOMAIN_ID),
        'PYTHONUNBUFFERED': '1',
        'ROS_PYTHON_CHECK_FIELDS': '1',  # a wrongly typed field raises instead of garbage
        'MOCAP_ROS2_NO_DEFER': '1',  # test this project's ros2 even where a real one exists
    })
    env.pop('ROS_LOCALHOST_ONLY', None)
    return env


@pytest.fixture(scope='session')
def ros2_cmd() -> list[str]:
    """Command prefix that runs this project's ``ros2`` (independent of the PATH)."""
    return [sys.executable, '-m', 'mocap_core.cli.ros2']


@pytest.fixture
def peer(ros_env):
    """An rclpy participant in this process on the test session's domain
    (:class:`mocap_core.ros_peer.RosPeer`): subscribe, publish, spin; closed at teardown."""
    from mocap_core.ros_peer import RosPeer
    p = RosPeer('test_peer', int(ros_env['ROS_DOMAIN_ID']))
    yield p
    p.close()


class Processes:
    """Background processes of one test, with their output in log files; stopped at teardown."""

    def __init__(self, env: dict[str, str], directory: Path) -> None:
        self.env = env
        self.directory = directory
        self.procs: list[tuple[subprocess.Popen, Path]] = []

    def start(self, cmd: list[str], name: str, **kwargs) -> tuple[subprocess.Popen, Path]:
        log = self.directory / f'{name}.log'
        stream = log.open('wb')
        proc = subprocess.Popen(cmd, env=kwargs.pop('env', self.env), stdout=stream,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, **kwargs)
        stream.close()
        self.procs.append((proc, log))
        return proc, log

    @staticmethod
    def wait_for_text(log: Path, text: str, timeout: float, proc: subprocess.Popen | None = None,
                      count: int = 1) -> str:
        """Poll ``log`` until ``text`` occurs ``count`` times; return the log. Fails on timeout."""
        deadline = time.monotonic() + timeout
        content = ''
        while time.monotonic() < deadline:
            content = log.read_text(errors='replace') if log.exists() else ''
            if content.count(text) >= count:
                return content
            if proc is not None and proc.poll() is not None:
                break
            time.sleep(0.05)
        raise AssertionError(f'{text!r} (x{count}) not in {log.name} after {timeout:.0f} s '
                             f'(process exit code: {proc.poll() if proc else None}):\n{content}')

    def stop_all(self) -> None:
        for proc, _ in self.procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        for proc, _ in self.procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=10)


@pytest.fixture
def processes(ros_env: dict[str, str], tmp_path: Path):
    procs = Processes(ros_env, tmp_path)
    yield procs
    procs.stop_all()
