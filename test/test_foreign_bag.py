"""A bag recorded on another rig: its own topic names and a robot's JointState of several joints.

compare, diagnose and identify thermal read it with ``--topic CONTRACT=RECORDED`` and ``--joint NAME``
(sma_wrist.contract.Recording) as they read a bag that follows msg_defs/topics.yaml, and say what to give
when they cannot."""

from __future__ import annotations

import json

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from sma_wrist.cli import main

TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)
RENAMED = {
    '/wrist/joint_states': '/joint_states',
    '/wrist/reference': '/wrist_controller/reference',
    '/wrist/muscle_1/temperature': '/sma/flexor/temperature',
    '/wrist/muscle_2/temperature': '/sma/extensor/temperature',
    '/wrist/tem_1/command': '/tem/flexor/voltage',
    '/wrist/tem_2/command': '/tem/extensor/voltage',
}
OPTIONS = [x for c, r in RENAMED.items() for x in ('--topic', f'{c}={r}')] + ['--joint', 'wrist_flex']


def _robot(m):
    """The wrist's joint as a robot driver names it, beside two others (as a robot's /joint_states would)."""
    m.name = ['shoulder', 'wrist_flex', 'elbow']
    m.position = np.array([0.3, m.position[0], -1.2])
    m.velocity = np.array([0.0, m.velocity[0], 0.0]) if len(m.velocity) else np.array([], dtype=float)
    m.effort = np.array([0.0, m.effort[0], 0.0]) if len(m.effort) else np.array([], dtype=float)
    return m


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    """(a recorded run, the same run as another rig would have recorded it)."""
    from rosbags.rosbag2 import Reader, Writer

    d = tmp_path_factory.mktemp('foreign')
    ours, theirs = d / 'ours', d / 'theirs'
    assert main(['run', '--duration', '32', '--bag', str(ours), '--quiet']) == 0
    with Reader(ours) as r, Writer(theirs, version=8) as w:
        conns = {
            c.id: w.add_connection(RENAMED.get(c.topic, c.topic), c.msgtype, typestore=TYPESTORE) for c in r.connections
        }
        for c, t, raw in r.messages():
            if c.msgtype == 'sensor_msgs/msg/JointState':
                raw = TYPESTORE.serialize_cdr(_robot(TYPESTORE.deserialize_cdr(raw, c.msgtype)), c.msgtype)
            w.write(conns[c.id], t, raw)
    return ours, theirs


def test_compare_reads_another_rigs_bag_as_its_own(bags, capsys):
    ours, theirs = bags
    capsys.readouterr()
    assert main(['compare', str(ours), '--json']) == 0
    want = json.loads(capsys.readouterr().out)[0]
    assert main(['compare', str(theirs), '--json', *OPTIONS]) == 0
    got = json.loads(capsys.readouterr().out)[0]
    for key in ('max_error_pct', 'rms_error_pct', 'peak_command_V'):
        assert got[key] == want[key], key
    # without the options: what is missing, and how to name it
    assert main(['compare', str(theirs)]) == 2
    err = capsys.readouterr().err
    assert 'no messages on /wrist/joint_states, /wrist/reference' in err and '--topic CONTRACT=RECORDED' in err, err


def test_a_robots_joint_state_without_the_wrists_name_is_an_error_not_a_guess(bags, capsys):
    """A JointState of several joints none of which is the contract's: the first joint (here a shoulder) was read
    as the wrist's angle without a word."""
    _, theirs = bags
    no_joint = [x for x in OPTIONS[:-2]]
    capsys.readouterr()
    assert main(['compare', str(theirs), *no_joint]) == 2
    err = capsys.readouterr().err
    assert "['shoulder', 'wrist_flex', 'elbow']" in err and '--joint NAME' in err, err


def test_diagnose_and_identify_thermal_read_another_rigs_bag_as_their_own(bags):
    from sma_wrist.contract import Recording
    from sma_wrist.diagnose.data import load_run
    from sma_wrist.identify.thermal import load_bag

    ours, theirs = bags
    rec = Recording.from_options(OPTIONS[1::2][:-1], 'wrist_flex')
    a, b = load_run(ours), load_run(theirs, recording=rec)
    for field in ('t', 'u', 'T', 'q'):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field
    (ra, _), (rb, _) = load_bag(ours, 0.1), load_bag(theirs, 0.1, recording=rec)
    assert [np.array_equal(x.T, y.T, equal_nan=True) and np.array_equal(x.u, y.u) for x, y in zip(ra, rb)] == [True] * 2


@pytest.mark.parametrize(
    'spec,says',
    [
        ('/wrist/joint_states', 'give CONTRACT=RECORDED'),
        ('/joint_states=/wrist/joint_states', 'is not a contract topic'),
        ('wrist/joint_states=/js', 'give CONTRACT=RECORDED'),
    ],
)
def test_a_malformed_topic_option_is_a_clear_error(bags, capsys, spec, says):
    _, theirs = bags
    for cmd in (['compare', str(theirs)], ['diagnose', str(theirs)]):
        capsys.readouterr()
        assert main([*cmd, '--topic', spec]) == 2
        assert says in capsys.readouterr().err, cmd
