"""The one YAML writer of the model files and params files the package writes (sma_wrist/core/yaml_file.py)."""

from __future__ import annotations

import yaml

from sma_wrist.core.yaml_file import write_yaml_file


def test_a_file_is_its_comment_then_its_keys_in_the_writers_order(tmp_path):
    doc = {'format': 'x', 'version': 1, 'layers': [1.5, 2.0], 'fit': {'rms': 0.25, 'note': 'ok'}}
    p = write_yaml_file(tmp_path / 'new' / 'x.yaml', doc, 'what wrote it\n\nwhat it is for')
    assert p.read_text() == (
        '# what wrote it\n#\n# what it is for\n'
        'format: x\nversion: 1\nlayers:\n- 1.5\n- 2.0\nfit:\n  rms: 0.25\n  note: ok\n'
    )
    q = write_yaml_file(tmp_path / 'p.yaml', {'hardware_bridge': {'ros__parameters': {'tem_sign': [1, -1]}}}, 'x', True)
    assert q.read_text() == '# x\nhardware_bridge:\n  ros__parameters:\n    tem_sign: [1, -1]\n'


def test_a_comment_of_several_lines_stays_a_comment(tmp_path):
    """A diagnosis summary that runs over two lines was written into the params file's header as is: its second
    line was YAML, not a comment."""
    doc = {'plant_sim': {'ros__parameters': {'payload_kg': 0.3}}}
    p = write_yaml_file(tmp_path / 'x.yaml', doc, 'cause: none; a summary\nthat goes on: here', flow_lists=True)
    assert yaml.safe_load(p.read_text()) == doc
