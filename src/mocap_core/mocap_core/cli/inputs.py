"""What an input of ``mocap process`` is: a bag, an ``.mcap`` file or a video (no ROS
imports)."""

from __future__ import annotations

from pathlib import Path

VIDEO_SUFFIXES = {'.mp4', '.avi', '.mov', '.mkv', '.webm', '.m4v', '.mpg', '.mpeg'}


def is_bag(path: Path) -> bool:
    """A rosbag2 folder (``metadata.yaml`` or ``.mcap`` files inside) or an ``.mcap`` file."""
    path = Path(path)
    return (path.is_dir() and ((path / 'metadata.yaml').exists() or
                               any(path.glob('*.mcap')))) or path.suffix == '.mcap'
