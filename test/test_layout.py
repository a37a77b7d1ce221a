"""The package layout holds (issue 15): no import cycle between the project's modules, the
core imports nothing of the node packages, and starting a node imports no training code.

The import graph is read from the source with ``ast`` (every ``import`` statement, at module
level or inside functions), so a lazy import cannot hide a cycle or an upward dependency.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path
from typing import Dict, List, Set

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / 'src'
PACKAGES = ('mocap_core', 'mocap_keypoints', 'mocap_lifter', 'mocap_physics', 'mocap_global')
NODE_PACKAGES = PACKAGES[1:]


def _modules() -> Dict[str, Path]:
    """Every module of the five packages: dotted name -> file."""
    found = {}
    for pkg in PACKAGES:
        base = SRC / pkg
        for path in sorted((base / pkg).rglob('*.py')):
            rel = path.relative_to(base).with_suffix('')
            parts = list(rel.parts)
            if parts[-1] == '__init__':
                parts = parts[:-1]
            found['.'.join(parts)] = path
    return found


def _resolve(name: str, modules: Dict[str, Path]) -> str:
    """The longest prefix of ``name`` that is one of our modules ('' if none)."""
    parts = name.split('.')
    while parts:
        candidate = '.'.join(parts)
        if candidate in modules:
            return candidate
        parts.pop()
    return ''


def import_graph() -> Dict[str, Set[str]]:
    """module -> the project modules it imports (directly, anywhere in the file)."""
    modules = _modules()
    graph: Dict[str, Set[str]] = {m: set() for m in modules}
    for module, path in modules.items():
        package = module if path.name == '__init__.py' else module.rpartition('.')[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets: List[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split('.')
                    base = base[:len(base) - (node.level - 1)]
                    prefix = '.'.join(base + ([node.module] if node.module else []))
                else:
                    prefix = node.module or ''
                targets = [f'{prefix}.{a.name}' for a in node.names] + [prefix]
            for target in targets:
                resolved = _resolve(target, modules)
                if resolved and resolved != module:
                    graph[module].add(resolved)
    return graph


def _cycles(graph: Dict[str, Set[str]]) -> List[List[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: Dict[str, int] = {}
    low: Dict[str, int] = {}
    stack: List[str] = []
    on_stack: Set[str] = set()
    out: List[List[str]] = []
    counter = [0]
    sys.setrecursionlimit(10000)

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def _is_package_init_pair(cycle: List[str], graph: Dict[str, Set[str]]) -> bool:
    """A package's ``__init__`` re-exporting its own submodules, which import siblings through
    the package: a facade, not a dependency cycle between concerns."""
    heads = {m for m in cycle if any(o.startswith(m + '.') for o in cycle)}
    return len(heads) == 1 and all(m == next(iter(heads)) or m.startswith(next(iter(heads)) + '.')
                                   for m in cycle) and not any(
        next(iter(heads)) in graph[m] for m in cycle if m not in heads)


def test_the_graph_sees_relative_lazy_and_absolute_imports():
    graph = import_graph()
    # a sample of known edges, so that a broken parser cannot pass the tests below vacuously
    assert 'mocap_core.rotations' in graph['mocap_core.kinematics']
    assert 'mocap_core.plugins' in graph['mocap_core.cli.process']
    assert any(m.startswith('mocap_core') for m in graph['mocap_lifter.node'])
    assert len(graph) > 80


def test_no_import_cycles():
    graph = import_graph()
    cycles = [c for c in _cycles(graph) if not _is_package_init_pair(c, graph)]
    assert cycles == [], 'import cycles: ' + '; '.join(' <-> '.join(c) for c in cycles)


def test_the_core_imports_no_node_package():
    graph = import_graph()
    upward = sorted(f'{m} -> {t}' for m, targets in graph.items() if m.startswith('mocap_core')
                    for t in targets if t.split('.')[0] in NODE_PACKAGES)
    assert upward == []


def test_no_runtime_module_imports_the_renderer():
    """Rendering is data generation: only the render package itself, the CLI and tests may
    import it (statically; the node start test below checks the running processes)."""
    graph = import_graph()
    bad = sorted(f'{m} -> {t}' for m, targets in graph.items()
                 if not m.startswith(('mocap_core.render', 'mocap_core.cli'))
                 and '.training' not in m
                 for t in targets if t.startswith('mocap_core.render'))
    assert bad == []


def test_node_packages_do_not_import_each_other_at_runtime():
    """A node package may use another's training code in its own training/evaluation, never
    in its runtime modules."""
    graph = import_graph()
    crossing = sorted(f'{m} -> {t}' for m, targets in graph.items()
                      if m.split('.')[0] in NODE_PACKAGES and '.training' not in m
                      for t in targets
                      if t.split('.')[0] in NODE_PACKAGES and t.split('.')[0] != m.split('.')[0])
    assert crossing == []


#: Modules that belong to training, evaluation, dataset building or reports, never to a
#: running node. (matplotlib and tqdm are not among them: MediaPipe's solutions package imports
#: the first, torch.hub the second.)
TRAINING_MODULES = ('mocap_core.data.dataset', 'mocap_core.data.splits',
                    'mocap_core.data.retarget', 'mocap_core.data.synth2d', 'mocap_core.data.bvh',
                    'mocap_core.data.bvh_synth', 'mocap_core.data.gt_bag', 'mocap_core.plots',
                    'mocap_core.demo_render', 'mocap_core.run_report', 'mocap_core.cli',
                    'mocap_core.testing', 'mocap_core.render',
                    # the renderer and body model of data generation (mocap data render)
                    'anny', 'pyrender', 'OpenGL', 'warp', 'trimesh')

START_NODE = '''
import json, sys
import rclpy
from rclpy.parameter import Parameter
from mocap_core.plugins import load_node_class
stage = sys.argv[1]
params = {'keypoints': [Parameter('source', value='topic')]}.get(stage, [])
context = rclpy.Context()
rclpy.init(args=[], context=context)
node = load_node_class(stage)(context=context, parameter_overrides=params)
print(json.dumps(sorted(sys.modules)))
getattr(node, 'shutdown', lambda: None)()
node.destroy_node()
context.try_shutdown()
'''


@pytest.mark.parametrize('stage', ['keypoints', 'lifter', 'physics', 'gmr'])
def test_starting_a_node_imports_no_training_code(stage):
    out = subprocess.run([sys.executable, '-c', START_NODE, stage], capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    loaded = json.loads(out.stdout.strip().splitlines()[-1])
    node_module = {'keypoints': 'mocap_keypoints.node', 'lifter': 'mocap_lifter.node',
                   'physics': 'mocap_physics.node', 'gmr': 'mocap_global.node'}[stage]
    assert node_module in loaded       # the check looks at the right process
    bad = [m for m in loaded if '.training' in m
           or any(m == t or m.startswith(t + '.') for t in TRAINING_MODULES)]
    assert bad == []
