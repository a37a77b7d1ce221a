"""Declaring node parameters with descriptions, types and ranges in one table.

Example::

    PARAMS = (
        ParamSpec('source', 'openpose_json', 'Input: camera | video | images | topic | ...'),
        ParamSpec('fps', 30.0, 'Playback rate in frames per second', min_value=0.1),
    )
    values = declare_parameters(node, PARAMS)   # -> {'source': ..., 'fps': ...}
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, Iterable, Optional

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: name, default (its type is the parameter's type), description."""

    name: str
    default: Any
    description: str
    read_only: bool = False
    min_value: Optional[float] = None
    max_value: Optional[float] = None
    additional_constraints: str = ''

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(description=self.description, read_only=self.read_only,
                                additional_constraints=self.additional_constraints)
        if self.min_value is not None or self.max_value is not None:
            lo = self.min_value if self.min_value is not None else -1e300
            hi = self.max_value if self.max_value is not None else 1e300
            if isinstance(self.default, bool):
                pass
            elif isinstance(self.default, int):
                d.integer_range = [IntegerRange(from_value=int(max(lo, -2**63)),
                                                to_value=int(min(hi, 2**63 - 1)), step=0)]
            elif isinstance(self.default, float):
                d.floating_point_range = [FloatingPointRange(from_value=float(lo),
                                                             to_value=float(hi), step=0.0)]
        return d


def declare_parameters(node, specs: Iterable[ParamSpec]) -> Dict[str, Any]:
    """Declare every spec on ``node`` and return ``{name: current value}``.

    An integer given for a floating-point parameter (``-p kp_joint:=6400``, ``mocap process
    --param physics.kp_joint=6400``) is taken as that number, not refused for its type: rclpy
    alone would raise ``InvalidParameterTypeException`` and the node would not start."""
    from rclpy.parameter import Parameter

    overrides = getattr(node, '_parameter_overrides', None)
    values: Dict[str, Any] = {}
    for spec in specs:
        given = overrides.get(spec.name) if isinstance(overrides, dict) else None
        if (given is not None and isinstance(spec.default, float)
                and given.type_ == Parameter.Type.INTEGER):
            overrides[spec.name] = Parameter(spec.name, value=float(given.value))
        param = node.declare_parameter(spec.name, spec.default, spec.descriptor())
        values[spec.name] = param.value
    return values


def describe_parameters(specs: Iterable[ParamSpec]) -> str:
    """Markdown table of the parameters (for READMEs and --help)."""
    rows = ['| parameter | default | description |', '|---|---|---|']
    rows += [f'| `{s.name}` | `{s.default!r}` | {s.description} |' for s in specs]
    return '\n'.join(rows)


def help_requested(argv, doc: str, specs: Iterable[ParamSpec]) -> bool:
    """If ``argv`` asks for ``-h``/``--help``, print the node's ``doc`` and its parameter
    table and return True (the node's ``main`` then exits 0 without starting ROS)."""
    if '-h' not in argv and '--help' not in argv:
        return False
    print(doc)
    print('Parameters (--ros-args -p name:=value):')
    print(describe_parameters(specs))
    return True


def spin_node(make_node, args, name: str) -> int:
    """Run a node until shutdown: ``rclpy.init(args)``, build it with ``make_node()``, spin.

    Returns the exit code: 0 after Ctrl-C or an external shutdown; 2 with a one-line
    ``<name>: error: ...`` on stderr when building the node raises FileNotFoundError or
    ValueError (missing or unreadable weights, a bad parameter). The executor is the one
    ``$MOCAP_EXECUTOR`` names (:mod:`mocap_core.executors`). Once the node runs, an
    exception that escapes a callback (nodes wrap theirs with :func:`mocap_core.guard.guarded`,
    so this is a last resort) is counted and logged like a guarded one, and spinning goes on:
    a frame that fails never stops the node. Always destroys the node and shuts down."""
    import sys

    from rclpy.executors import ExternalShutdownException

    from .executors import close_nodes, init_rclpy, make_executor, spin_until
    from .guard import record_failure

    signals = init_rclpy(args)
    node = executor = None
    try:
        try:
            node = make_node()
        except (FileNotFoundError, ValueError) as exc:
            print(f'{name}: error: {exc}', file=sys.stderr)
            return 2
        executor = make_executor()
        executor.add_node(node)
        spin_until(executor, lambda: not signals.requested and node.context.ok(),
                   lambda exc: record_failure(node, 'callback', exc))
        return 0
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        try:
            close_nodes(executor, [node], label=name)
        finally:
            signals.restore()


def camera_pose_params(topic_description: str, missing: str) -> tuple:
    """The four parameters of a known camera pose (``camera_pose_topic``, ``_type``,
    ``_convention``, ``_max_age_s``; :class:`mocap_core.camera_pose.KnownCameraPoses`), shared
    by the nodes that take one. ``topic_description``: what the node does with the pose;
    ``missing``: what happens to a frame without a pose near it."""
    return (
        ParamSpec('camera_pose_topic', '', "The camera's known pose in a world frame (a "
                  "robot's odom or map pose of its camera): " + topic_description,
                  read_only=True),
        ParamSpec('camera_pose_type', 'odometry', "Message type on camera_pose_topic: "
                  "'odometry' (nav_msgs/Odometry) or 'pose' (geometry_msgs/PoseStamped)",
                  read_only=True, additional_constraints='odometry or pose'),
        ParamSpec('camera_pose_convention', 'optical', "Which frame the camera pose is of: "
                  "'optical' (x right, y down, z forward) or 'body' (REP-103 camera link: x "
                  "forward, y left, z up)", read_only=True,
                  additional_constraints='optical or body'),
        ParamSpec('camera_pose_max_age_s', 0.1, "A camera pose further than this from a "
                  "frame's stamp does not serve it (" + missing + ')', min_value=0.0),
    )
