"""The launch file (for full ROS 2 installs; `launch` is not installable here): it parses,
starts executables that exist, with parameters the nodes declare, and records every topic the
demo records."""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
LAUNCH = ROOT / 'src' / 'mocap_core' / 'launch' / 'pipeline.launch.py'


def _calls(tree, name):
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(
        n.func, 'id', getattr(n.func, 'attr', None)) == name]


def test_launch_file_starts_the_four_nodes_with_declared_parameters():
    import importlib

    tree = ast.parse(LAUNCH.read_text())
    nodes = {}
    for call in _calls(tree, 'Node'):
        kw = {k.arg: k.value for k in call.keywords}
        pkg, exe = ast.literal_eval(kw['package']), ast.literal_eval(kw['executable'])
        params = [k.value for k in kw['parameters'].elts[0].keys]
        nodes[(pkg, exe)] = params
    assert set(nodes) == {('mocap_keypoints', 'keypoints'), ('mocap_lifter', 'lifter'),
                          ('mocap_physics', 'physics'), ('mocap_global', 'gmr')}
    for (pkg, exe), params in nodes.items():
        setup = (ROOT / 'src' / pkg / 'setup.py').read_text()
        assert re.search(rf"'{exe} = {pkg}\.node:main'", setup), (pkg, exe)
        declared = {s.name for s in importlib.import_module(f'{pkg}.node').PARAMETERS}
        assert set(params) <= declared, (pkg, set(params) - declared)


def test_launch_file_records_the_demo_topics():
    tree = ast.parse(LAUNCH.read_text())
    assign = next(n for n in ast.walk(tree) if isinstance(n, ast.Assign)
                  and getattr(n.targets[0], 'id', '') == 'TOPICS')
    from mocap_core import topics

    namespace = {'topics': topics}   # the launch file takes the list from mocap_core.topics
    exec(compile(ast.Module([assign], []), str(LAUNCH), 'exec'), namespace)  # noqa: S102
    demo = (ROOT / 'scripts' / 'demo.sh').read_text()
    fixed = re.search(r'topics=\(([^)]*)\)', demo).group(1).split()
    expected = set(fixed) | {f'/mocap/{s}/{leaf}' for s in ('lifter', 'physics', 'world')
                             for leaf in ('motion', 'joints3d', 'joint_states', 'markers')}
    # several people: the ids, the TF tree and every stage's combined messages
    expected |= {'/humans/bodies/tracked', '/tf', '/mocap/lifter/bodies/contacts',
                 '/mocap/lifter/bodies/bone_lengths',
                 '/mocap/lifter/bodies/unsmoothed_motion'} | {
        f'/mocap/{s}/bodies/{leaf}' for s in ('lifter', 'physics', 'world')
        for leaf in ('motion', 'joints3d', 'markers')}
    assert set(namespace['TOPICS']) == expected


def test_launch_file_passes_the_executor_choice_to_the_nodes():
    """`executor:=...` sets MOCAP_EXECUTOR for the node processes, its default is the
    project's."""
    from mocap_core.executors import DEFAULT, ENV

    tree = ast.parse(LAUNCH.read_text())
    declared = {ast.literal_eval(c.args[0]): {k.arg: k.value for k in c.keywords}
                for c in _calls(tree, 'DeclareLaunchArgument')}
    assert ast.literal_eval(declared['executor']['default_value']) == DEFAULT
    (setenv,) = _calls(tree, 'SetEnvironmentVariable')
    assert ast.literal_eval(setenv.args[0]) == ENV
    assert ast.literal_eval(setenv.args[1].args[0]) == 'executor'
    ret = next(n for n in ast.walk(tree) if isinstance(n, ast.Return))
    # the variable is set before the nodes start
    names = [e.id for e in ret.value.args[0].right.elts]
    assert names.index('executor') < min(names.index(n) for n in
                                          ('lifter', 'physics', 'gmr', 'keypoints'))
