"""How the core finds the pipeline's node packages without naming them (no ROS imports).

Each node package registers its parts under Python entry points in its ``setup.py``, the way
``ros2cli`` finds its verbs, so that the core imports nothing above it:

* ``mocap.nodes``: ``<stage> = <package>.node:<NodeClass>``, the rclpy node class of a
  pipeline stage (``mocap process``, ``mocap bench pipeline``, ``ros2 run`` names);
* ``mocap.commands``: ``<name> = <package>.training.cli``, a module with
  ``add_train_parser(sub)`` and ``add_eval_parser(sub)`` (``mocap train|eval``);
* ``mocap.benches``: ``<stage> = <package>.bench:main``, a benchmark taking its own argv
  (``mocap bench <stage>``);
* ``mocap.detectors``: ``<name> = <package>.detector:<Class>``, a 2D keypoint detector as the
  keypoint node runs it (``detect(bgr) -> (P, 23, 3)``, ``reset()``, ``close()``), for data
  generation (``mocap data render``).

The stage names and their order are part of the design contract (:data:`PIPELINE`); which
package provides a stage is not.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any, Dict, List, Optional

NODE_GROUP = 'mocap.nodes'
COMMAND_GROUP = 'mocap.commands'
BENCH_GROUP = 'mocap.benches'
DETECTOR_GROUP = 'mocap.detectors'

#: The pipeline's stages, upstream first (design contract).
PIPELINE = ('keypoints', 'lifter', 'physics', 'gmr')


class PluginError(RuntimeError):
    """A stage or command that no installed package provides, or one that fails to load."""


def _group(group: str) -> Dict[str, EntryPoint]:
    found: Dict[str, EntryPoint] = {}
    for ep in entry_points(group=group):
        found.setdefault(ep.name, ep)
    return found


def _order(name: str) -> tuple:
    return (PIPELINE.index(name) if name in PIPELINE else len(PIPELINE), name)


@dataclass(frozen=True)
class NodePlugin:
    """One stage's node: ``stage``, the providing ``package`` (distribution name) and
    ``executable`` (its ``ros2 run`` name), and the entry point of its class."""

    stage: str
    package: str
    executable: str
    entry_point: EntryPoint

    def load(self) -> type:
        """The node class (imports the node module, and with it rclpy)."""
        try:
            return self.entry_point.load()
        except Exception as exc:  # noqa: BLE001 - one line for the user
            raise PluginError(f'cannot load the {self.stage} node ({self.entry_point.value}): '
                              f'{type(exc).__name__}: {exc}') from exc


def nodes() -> Dict[str, NodePlugin]:
    """The installed stages, in pipeline order: ``{stage: NodePlugin}``."""
    out: Dict[str, NodePlugin] = {}
    for name in sorted(_group(NODE_GROUP), key=_order):
        ep = _group(NODE_GROUP)[name]
        package = ep.dist.name if ep.dist is not None else ep.module.split('.')[0]
        executable = name
        if ep.dist is not None:
            for script in ep.dist.entry_points:
                if script.group == 'console_scripts' and script.module == ep.module:
                    executable = script.name
                    break
        out[name] = NodePlugin(name, package, executable, ep)
    return out


def node_plugin(stage: str) -> NodePlugin:
    """The plugin of one stage; raises PluginError when no package provides it."""
    found = nodes()
    if stage not in found:
        raise PluginError(f"no installed package provides the {stage!r} node (entry point "
                          f"group {NODE_GROUP}; installed: {', '.join(found) or 'none'})")
    return found[stage]


def load_node_class(stage: str) -> type:
    """The rclpy node class of ``stage`` (``keypoints``, ``lifter``, ``physics``, ``gmr``)."""
    return node_plugin(stage).load()


def command_modules(warn: bool = True) -> List[Any]:
    """The modules registered under ``mocap.commands``, in pipeline order. A module that fails
    to import is skipped with a one-line warning on stderr (``mocap --help`` keeps working)."""
    modules = []
    group = _group(COMMAND_GROUP)
    for name in sorted(group, key=_order):
        try:
            modules.append(group[name].load())
        except Exception as exc:  # noqa: BLE001 - a broken plugin must not break the CLI
            if warn:
                print(f'mocap: warning: commands of {group[name].value} unavailable '
                      f'({type(exc).__name__}: {exc})', file=sys.stderr)
    return modules


def benches() -> Dict[str, EntryPoint]:
    """``{stage: entry point of its benchmark's main(argv)}``, in pipeline order."""
    group = _group(BENCH_GROUP)
    return {name: group[name] for name in sorted(group, key=_order)}


def run_bench(stage: str, argv: Optional[List[str]] = None) -> int:
    """Run the benchmark of ``stage`` with ``argv``; raises PluginError when none exists."""
    found = benches()
    if stage not in found:
        raise PluginError(f'no benchmark registered for {stage!r} (installed: '
                          f"{', '.join(found) or 'none'})")
    return int(found[stage].load()(argv) or 0)


def detector_class(name: str = 'blazepose') -> type:
    """The keypoint detector class registered as ``name`` under ``mocap.detectors``."""
    group = _group(DETECTOR_GROUP)
    if name not in group:
        raise PluginError(f'no installed package provides the {name!r} detector (entry point '
                          f"group {DETECTOR_GROUP}; installed: {', '.join(group) or 'none'})")
    try:
        return group[name].load()
    except Exception as exc:  # noqa: BLE001 - one line for the user
        raise PluginError(f'cannot load the {name} detector ({group[name].value}): '
                          f'{type(exc).__name__}: {exc}') from exc
