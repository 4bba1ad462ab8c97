"""Parameter semantics of the embedded rclpy (rclpy/node.py, Humble)."""

from __future__ import annotations

import pytest

from sma_wrist import runtime

runtime.activate()

import rclpy  # noqa: E402
from rcl_interfaces.msg import (  # noqa: E402
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterEvent,
    SetParametersResult,
)
from rclpy.exceptions import (  # noqa: E402
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterAlreadyDeclaredException,
    ParameterNotDeclaredException,
)
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402


@pytest.fixture
def ros():
    def init(args=None):
        rclpy.init(args=args)

    yield init
    rclpy.try_shutdown()


def test_embedded_is_active():
    assert runtime.using_embedded()
    assert getattr(rclpy, '__embedded__', False)
    import rclpy.node as rn

    from sma_wrist.runtime.rclpy import node as en

    assert rn.Node is en.Node


def test_use_sim_time_declared_automatically(ros):
    ros()
    n = Node('n')
    assert n.has_parameter('use_sim_time')
    assert n.get_parameter('use_sim_time').value is False


def test_floating_point_range_and_step(ros):
    ros()
    n = Node('n')
    d = ParameterDescriptor(floating_point_range=[FloatingPointRange(from_value=0.0, to_value=1.0, step=0.25)])
    assert n.declare_parameter('k', 0.5, d).value == 0.5
    ok, out, step, edge = n.set_parameters(
        [
            Parameter('k', value=0.75),
            Parameter('k', value=1.5),
            Parameter('k', value=0.3),
            Parameter('k', value=1.0 + 1e-9),
        ]
    )
    assert ok.successful
    assert not out.successful
    assert out.reason == 'Parameter k out of range Min: 0.0, Max: 1.0, value: 1.5'
    assert not step.successful and 'not close enough to a valid step' in step.reason
    assert edge.successful  # edges accepted within PARAM_REL_TOL
    assert n.get_parameter('k').value == pytest.approx(1.0)


def test_integer_range_step(ros):
    ros()
    n = Node('n')
    d = ParameterDescriptor(integer_range=[IntegerRange(from_value=0, to_value=10, step=2)])
    n.declare_parameter('i', 4, d)
    r = n.set_parameters([Parameter('i', value=5)])[0]
    assert not r.successful
    assert r.reason == 'The parameter value for i is not a valid step. Min: 0, max: 10, value: 5, step: 2'
    assert n.get_parameter('i').value == 4
    with pytest.raises(InvalidParameterValueException):
        n.declare_parameter(
            'j', 11, ParameterDescriptor(integer_range=[IntegerRange(from_value=0, to_value=10, step=1)])
        )


def test_read_only_and_type_mismatch(ros):
    ros()
    n = Node('n')
    n.declare_parameter('ro', 1.0, ParameterDescriptor(read_only=True))
    r = n.set_parameters([Parameter('ro', value=2.0)])[0]
    assert not r.successful and r.reason == 'Trying to set a read-only parameter: ro.'
    n.declare_parameter('x', 1.0)
    r = n.set_parameters([Parameter('x', value=1)])[0]
    assert not r.successful
    assert r.reason == "Wrong parameter type, expected 'Type.DOUBLE' got 'Type.INTEGER'"
    n.declare_parameter('dyn', 1.0, ParameterDescriptor(dynamic_typing=True))
    assert n.set_parameters([Parameter('dyn', value='text')])[0].successful
    with pytest.raises(ParameterNotDeclaredException):
        n.set_parameters([Parameter('nope', value=1)])
    with pytest.raises(ParameterAlreadyDeclaredException):
        n.declare_parameter('x', 2.0)


def test_override_of_wrong_type_raises_at_declare(ros):
    ros(['--ros-args', '-p', 'gain:=3'])
    n = Node('n')
    with pytest.raises(InvalidParameterTypeException):
        n.declare_parameter('gain', 1.0)


def test_callbacks_reject_with_reason_newest_first(ros):
    ros()
    n = Node('n')
    n.declare_parameter('limit', 1.0)
    calls = []

    def first(params):
        calls.append('first')
        return SetParametersResult(successful=True)

    def veto(params):
        calls.append('veto')
        bad = [p for p in params if p.name == 'limit' and p.value < 0]
        return SetParametersResult(successful=not bad, reason='limit must be >= 0' if bad else '')

    n.add_on_set_parameters_callback(first)
    n.add_on_set_parameters_callback(veto)
    r = n.set_parameters([Parameter('limit', value=-1.0)])[0]
    assert not r.successful and r.reason == 'limit must be >= 0'
    assert calls == ['veto']  # newest first, stops at the first rejection
    assert n.get_parameter('limit').value == 1.0
    n.remove_on_set_parameters_callback(veto)
    assert n.set_parameters([Parameter('limit', value=-1.0)])[0].successful
    assert n.get_parameter('limit').value == -1.0


def test_parameter_events_published(ros):
    ros()
    events = []
    n = Node('n')
    listener = Node('listener')
    listener.create_subscription(ParameterEvent, '/parameter_events', events.append, 100)
    n.declare_parameter('a', 1)
    n.set_parameters([Parameter('a', value=2)])
    ex = rclpy.executors.SingleThreadedExecutor()
    ex.add_node(listener)
    ex.run_until(0)
    mine = [e for e in events if e.node == '/n']
    assert [p.name for p in mine[0].new_parameters] == ['a']
    assert mine[1].changed_parameters[0].value.integer_value == 2


def test_params_file_wildcards_namespaces_and_cli_order(ros, tmp_path):
    f = tmp_path / 'p.yaml'
    f.write_text(
        '/**:\n  ros__parameters:\n    common: 1\n    gain: 0.5\n'
        'ctrl:\n  ros__parameters:\n    gain: 2.0\n    nested:\n      k: [1.0, 2.0]\n    name: "007"\n'
        '/robot:\n  ctrl:\n    ros__parameters:\n      gain: 9.0\n'
    )
    ros(['--ros-args', '--params-file', str(f), '-p', 'ctrl:common:=5', '-p', 'flag:=true'])
    a = Node('ctrl')
    b = Node('other')
    c = Node('ctrl', namespace='robot')
    assert a.declare_parameter('gain', 0.0).value == 2.0
    assert a.declare_parameter('common', 0).value == 5  # -p after the file wins
    assert a.declare_parameter('nested.k', [0.0]).value == [1.0, 2.0]
    assert a.declare_parameter('name', '').value == '007'  # quoted stays a string
    assert a.declare_parameter('flag', False).value is True
    assert b.declare_parameter('gain', 0.0).value == 0.5
    assert b.declare_parameter('common', 0).value == 1
    assert c.declare_parameter('gain', 0.0).value == 9.0
    # declare_parameters with a namespace looks overrides up by the full name
    assert [p.value for p in a.declare_parameters('nested', [('q', 3)])] == [3]


def test_params_merge_by_node_key_in_order_of_first_appearance_as_rcl_does(ros, tmp_path):
    """A later file's /** does not beat an earlier file's node section (rcl's table is keyed by
    node name in first-appearance order); a later section of the same node does. This is what
    made launch arguments silently lose to config/wrist.yaml under ROS 2 Humble."""
    base, wild, own = tmp_path / 'base.yaml', tmp_path / 'wild.yaml', tmp_path / 'own.yaml'
    base.write_text('/**:\n  ros__parameters:\n    use_it: true\nplant:\n  ros__parameters:\n    load: 0.3\n')
    wild.write_text('/**:\n  ros__parameters:\n    load: 0.5\n')
    own.write_text('plant:\n  ros__parameters:\n    load: 0.7\n')
    ros(['--ros-args', '--params-file', str(base), '--params-file', str(wild)])
    assert Node('plant').declare_parameter('load', 0.0).value == 0.3
    assert Node('other').declare_parameter('load', 0.0).value == 0.5
    rclpy.shutdown()
    ros(['--ros-args', '--params-file', str(base), '--params-file', str(wild), '--params-file', str(own)])
    assert Node('plant').declare_parameter('load', 0.0).value == 0.7


def test_cli_args_remap_and_constructor_overrides(ros):
    ros(['--ros-args', '-p', 'x:=1'])
    n = Node(
        'orig',
        cli_args=['--ros-args', '-r', '__node:=renamed', '-p', 'x:=2'],
        parameter_overrides=[Parameter('y', value='o')],
    )
    assert n.get_name() == 'renamed'
    assert n.declare_parameter('x', 0).value == 2  # node args after global ones
    assert n.declare_parameter('y', '').value == 'o'
    m = Node(
        'free',
        use_global_arguments=False,
        automatically_declare_parameters_from_overrides=True,
        parameter_overrides=[Parameter('z', value=1.5)],
    )
    assert m.get_parameter('z').value == 1.5
    assert not m.has_parameter('x')


def test_bad_argument_is_a_typed_error(ros):
    from sma_wrist.runtime.errors import ArgumentError

    with pytest.raises(ArgumentError):
        rclpy.init(args=['--ros-args', '--bogus'])


@pytest.mark.parametrize(
    'content, message',
    [
        (b'\xff\xfe\x00garbage\x80: 1\n', 'not a UTF-8 text file'),  # a binary file named .yaml
        (b'a: [unclosed\n', "invalid YAML: expected ',' or ']'"),
    ],
)
def test_unreadable_params_file_is_one_line_error_naming_it(tmp_path, capsys, content, message):
    """sma-wrist run --params-file: a binary or malformed file is `error: FILE: ...` on one line, exit 2."""
    from sma_wrist.cli import main

    f = tmp_path / 'params.yaml'
    f.write_bytes(content)
    assert main(['run', '--duration', '1', '--quiet', '--params-file', str(f)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f'error: {f}: ') and message in err and err.count('\n') == 1, err
