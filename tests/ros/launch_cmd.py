"""Evaluates a ROS 2 launch file as `ros2 launch FILE name:=value ...` would,
with the stand-ins in tests/ros/launch_stub/ for `launch` and `launch_ros`
(not on PyPI), and prints or runs each node's command line.

    python3 tests/ros/launch_cmd.py FILE [name:=value ...] [--describe] [--exec]

--describe prints the declared launch arguments as JSON; otherwise the node
commands are printed as JSON (one list per node), or with --exec the one node
is exec'd (so the caller's $! is the node). Unknown launch arguments and
missing required ones are refused, as ros2 launch refuses them.
"""

import importlib.util
import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), 'launch_stub'))

from launch import LaunchContext  # noqa: E402
from launch.actions import DeclareLaunchArgument, OpaqueFunction  # noqa: E402
from launch_ros.actions import Node  # noqa: E402


def load(path):
    spec = importlib.util.spec_from_file_location('launch_file', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.generate_launch_description()


def nodes(entities, context):
    out = []
    for e in entities:
        if isinstance(e, DeclareLaunchArgument):
            continue
        if isinstance(e, OpaqueFunction):
            out += nodes(e.function(context, *e.args, **e.kwargs) or [], context)
        elif isinstance(e, Node):
            out.append(e.command(context))
        else:
            raise TypeError(f"action the stand-in does not implement: {e!r}")
    return out


def main():
    args = sys.argv[1:]
    flags = {a for a in args if a.startswith('--')}
    rest = [a for a in args if not a.startswith('--')]
    description = load(rest[0])
    declared = [e for e in description.entities if isinstance(e, DeclareLaunchArgument)]
    if '--describe' in flags:
        print(json.dumps({d.name: {'default': d.default_value, 'description': d.description}
                          for d in declared}))
        return
    given = dict(a.split(':=', 1) for a in rest[1:])
    names = {d.name for d in declared}
    unknown = set(given) - names
    if unknown:
        sys.exit(f"unknown launch arguments {sorted(unknown)}; declared: {sorted(names)}")
    config = {d.name: d.default_value for d in declared if d.default_value is not None}
    config.update(given)
    missing = names - set(config)
    if missing:
        sys.exit(f"launch arguments without a value: {sorted(missing)}")
    commands = nodes(description.entities, LaunchContext(config))
    if '--exec' in flags:
        if len(commands) != 1:
            sys.exit(f"--exec needs one node; the launch file starts {len(commands)}")
        print('launch: ' + ' '.join(commands[0]), file=sys.stderr, flush=True)
        os.execv(commands[0][0], commands[0])
    print(json.dumps(commands))


if __name__ == '__main__':
    main()
