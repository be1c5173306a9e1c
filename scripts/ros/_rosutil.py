"""Shared helpers of the rclpy stand-ins for the ros2 CLI (echo, call, play_bag).

Message types by name, messages to and from plain dicts (no rosidl_runtime_py
in the PyPI wheels), and a clear message when the environment is not set up.
"""

import importlib
import re
import sys

SETUP_HINT = (
    "set up with: scripts/setup_venv.sh && scripts/build_msgs.sh && . build/msgs/env.sh\n"
    "and on a machine without a ROS network run under scripts/netns.sh"
)


def require_rclpy():
    """Imports rclpy, or exits with how to set the environment up."""
    try:
        import rclpy  # noqa: F401
    except ImportError as e:
        sys.exit(f"error: cannot import rclpy ({e});\n{SETUP_HINT}")
    return sys.modules["rclpy"]


def import_type(name):
    """'pkg/msg/Type', 'pkg/srv/Type' or 'pkg/Type' (msg) to the Python class."""
    parts = name.strip("/").split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or parts[1] not in ("msg", "srv", "action"):
        sys.exit(f"error: {name!r} is not a type name like pkg/msg/Type or pkg/srv/Type")
    try:
        module = importlib.import_module(f"{parts[0]}.{parts[1]}")
        return getattr(module, parts[2])
    except (ImportError, AttributeError) as e:
        sys.exit(f"error: cannot load type {name!r} ({e});\n{SETUP_HINT}")


_SEQ = re.compile(r"^sequence<([^,>]+)(?:,\s*\d+)?>$|^([^\[]+)\[\d*\]$")


def _element_class(type_str):
    """The message class of a nested field type string, or None for primitives."""
    if "/" not in type_str:
        return None
    pkg, typ = type_str.split("/", 1)
    return getattr(importlib.import_module(f"{pkg}.msg"), typ.split("/")[-1])


def fill(msg, data, path=""):
    """Sets the fields of `msg` from a dict (nested dicts and lists allowed)."""
    if data is None:
        return msg
    if not isinstance(data, dict):
        raise ValueError(f"{path or 'message'}: expected a mapping, got {data!r}")
    types = msg.get_fields_and_field_types()
    for key, value in data.items():
        if key not in types:
            raise ValueError(
                f"{path}{key}: no such field in {type(msg).__name__} (fields: {', '.join(types)})"
            )
        ftype = types[key]
        m = _SEQ.match(ftype)
        if m:
            elem = _element_class(m.group(1) or m.group(2))
            if not isinstance(value, list):
                raise ValueError(f"{path}{key}: expected a list")
            if elem is not None:
                value = [fill(elem(), v, f"{path}{key}[{i}].") for i, v in enumerate(value)]
            setattr(msg, key, value)
        elif _element_class(ftype) is not None:
            fill(getattr(msg, key), value, f"{path}{key}.")
        else:
            try:
                setattr(msg, key, value)
            except (AssertionError, TypeError, ValueError) as e:
                raise ValueError(f"{path}{key}: {value!r} does not fit {ftype} ({e})") from e
    return msg


def to_plain(msg):
    """A message as nested dicts/lists of Python scalars (for YAML or JSON)."""
    if hasattr(msg, "get_fields_and_field_types"):
        return {k: to_plain(getattr(msg, k)) for k in msg.get_fields_and_field_types()}
    if isinstance(msg, (list, tuple)) or type(msg).__name__ in ("array", "ndarray"):
        return [to_plain(x) for x in msg]
    if hasattr(msg, "item"):  # numpy scalar
        return msg.item()
    if isinstance(msg, bytes):  # a `byte` field (DiagnosticStatus.level): its number(s)
        return msg[0] if len(msg) == 1 else list(msg)
    return msg


def qos_profile(reliable=True, depth=10, transient_local=False):
    """A QoS profile for our topics (the node's default: reliable, volatile)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if transient_local else DurabilityPolicy.VOLATILE,
    )


# How long one spin_once may block while a bench waits for a message: it
# returns as soon as a callback has run, so a longer step adds no latency,
# while a short one makes rclpy poll (a wait set rebuilt each time) and
# takes CPU from the node under test.
WAIT_STEP = 0.05


def spin_until(rclpy, node, predicate, timeout, step=WAIT_STEP):
    """Spins `node` until `predicate()` is true or `timeout` seconds pass."""
    import time

    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() >= deadline:
            return False
        rclpy.spin_once(node, timeout_sec=step)
    return True


def vectors(flat, d):
    """Flat coordinates, d per particle (as a PredictedTrajectory carries them),
    as geometry_msgs/Vector3s with z = 0 in 2D."""
    from geometry_msgs.msg import Vector3

    flat = [float(x) for x in flat]
    pad = [0.0] * (3 - d)
    return [Vector3(**dict(zip("xyz", flat[i:i + d] + pad))) for i in range(0, len(flat), d)]


def predicted_states(traj):
    """The states of a compact mcgnode_msgs/PredictedTrajectory, each with the
    graph of `traj.initial` (types, masses, edges, anchors), its positions and
    velocities (Vector3s, z = 0 in 2D), its stamp in ns and its step number."""
    from types import SimpleNamespace

    init, n, d = traj.initial, len(traj.initial.positions), traj.initial.dimension
    t0 = traj.header.stamp.sec * 1_000_000_000 + traj.header.stamp.nanosec
    return [
        SimpleNamespace(
            positions=vectors(traj.positions[k * n * d:(k + 1) * n * d], d),
            velocities=vectors(traj.velocities[k * n * d:(k + 1) * n * d], d),
            types=init.types, masses=init.masses, edge_a=init.edge_a, edge_b=init.edge_b,
            anchors=init.anchors, system=init.system,
            stamp_ns=t0 + round((k + 1) * traj.dt * 1e9), step=init.step + k + 1,
        )
        for k in range(traj.steps)
    ]
