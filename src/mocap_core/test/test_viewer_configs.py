"""The RViz config and the Foxglove layout shipped for several people parse, and every topic
they show is one the pipeline publishes (a renamed topic breaks this test, not the viewer)."""

import json
from pathlib import Path

import yaml

from mocap_core import topics

ROOT = Path(__file__).resolve().parents[3]
PUBLISHED = set(topics.ALL) | {topics.BODIES_TRACKED, topics.ANNOTATED} | {
    topics.bodies_topic(stage, name) for stage in topics.STAGES
    for name in ('motion', 'joints3d', 'markers')}


def _topics(node):
    if isinstance(node, dict):
        for k, v in node.items():
            if k in ('Topic',) and isinstance(v, dict):
                yield v['Value']
            elif k in ('topicPath', 'imageTopic') and isinstance(v, str):
                yield v
            elif k == 'topics' and isinstance(v, dict):
                yield from v
            elif k == 'value' and isinstance(v, str) and v.startswith('/'):
                yield v.split('.')[0]
            else:
                yield from _topics(v)
    elif isinstance(node, list):
        for v in node:
            yield from _topics(v)


def test_rviz_config():
    cfg = yaml.safe_load((ROOT / 'config' / 'rviz' / 'mocap_people.rviz').read_text())
    vm = cfg['Visualization Manager']
    assert vm['Global Options']['Fixed Frame'] == 'world'
    classes = {d['Class'] for d in vm['Displays']}
    assert {'rviz_default_plugins/TF', 'rviz_default_plugins/MarkerArray'} <= classes
    shown = set(_topics(cfg))
    assert topics.bodies_topic('world', 'markers') in shown
    assert shown <= PUBLISHED, shown - PUBLISHED


def test_foxglove_layout():
    cfg = json.loads((ROOT / 'config' / 'foxglove' / 'mocap_people.json').read_text())
    assert cfg['configById']['3D!bodies']['followTf'] == 'world'
    shown = set(_topics(cfg))
    assert topics.BODIES_TRACKED in shown
    assert shown <= PUBLISHED, shown - PUBLISHED

    def leaves(node):
        if isinstance(node, str):
            yield node
        else:
            yield from leaves(node['first'])
            yield from leaves(node['second'])
    assert set(leaves(cfg['layout'])) == set(cfg['configById'])
