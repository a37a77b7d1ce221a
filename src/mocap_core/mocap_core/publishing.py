"""Lazy outputs: a message is built only when someone listens (issue 20).

Most of a stage's per-frame cost beyond its algorithm is building and serialising messages
nobody reads (markers, joint clouds, joint states, paths). :func:`publish_if_heard` builds
and publishes a message only while its publisher has a subscription; the main motion topic
and ``/diagnostics`` are always published by the nodes. In ``mocap process``
(:class:`mocap_core.inprocess.InProcessGraph`) the recorder counts as a subscriber of every
topic, so the output bag holds every topic as before.
"""

from __future__ import annotations

from typing import Any, Callable


def publish_if_heard(publisher: Any, build: Callable[[], Any]) -> bool:
    """``publisher.publish(build())`` if it has a subscription; returns whether it did."""
    if publisher.get_subscription_count() == 0:
        return False
    publisher.publish(build())
    return True
