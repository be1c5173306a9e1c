"""Stand-in for `launch_ros.actions.Node`: the command line launch_ros builds."""

import os
import tempfile

import yaml
from ament_index_python.packages import get_package_prefix
from launch.substitutions import perform


class Node:
    KNOWN = {'package', 'executable', 'name', 'namespace', 'parameters',
             'remappings', 'arguments', 'output'}

    def __init__(self, **kwargs):
        unknown = set(kwargs) - self.KNOWN
        if unknown:
            raise TypeError(f"Node arguments the stand-in does not implement: {sorted(unknown)}")
        self.kwargs = kwargs

    def command(self, context):
        """The argv launch_ros runs for this node (launch_ros actions/node.py)."""
        k = self.kwargs
        package = perform(k['package'], context)
        exe = perform(k['executable'], context)
        # ros2 run's and ExecutableInPackage's lookup.
        cmd = [os.path.join(get_package_prefix(package), 'lib', package, exe)]
        cmd += [perform(a, context) for a in k.get('arguments', [])]
        cmd.append('--ros-args')
        name = perform(k['name'], context) if 'name' in k else None
        if name is not None:
            cmd += ['-r', f'__node:={name}']
        ns = perform(k['namespace'], context) if 'namespace' in k else ''
        ns = ns if ns.startswith('/') else '/' + ns
        cmd += ['-r', f'__ns:={ns}']
        full = (ns.rstrip('/') + '/' + name) if name is not None else None
        for p in k.get('parameters', []):
            if isinstance(p, dict):
                values = {perform(key, context): perform(v, context) if not isinstance(
                    v, (bool, int, float)) else v for key, v in p.items()}
                f = tempfile.NamedTemporaryFile('w', prefix='launch_params_', delete=False)
                with f:
                    yaml.dump({full or '/**': {'ros__parameters': values}}, f,
                              default_flow_style=False)
                cmd += ['--params-file', f.name]
            else:
                path = perform(p, context)
                if not os.path.isfile(path):
                    raise FileNotFoundError(f"parameter file {path} does not exist")
                cmd += ['--params-file', path]
        for src, dst in k.get('remappings', []):
            cmd += ['-r', f'{perform(src, context)}:={perform(dst, context)}']
        return cmd
