#!/usr/bin/env bash
# Creates .venv at the repository root with the Python packages the tests and
# scripts use (independent bag decoders now; ROS 2 packages may be added below).
# Idempotent: packages already installed at the pinned version are not touched.
# Quiet unless something fails.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
LOG="$(mktemp)"
trap 'rm -f "$LOG"' EXIT

# Runs a command silently; on failure shows its output and stops.
run() {
    if ! "$@" >"$LOG" 2>&1; then
        cat "$LOG" >&2
        echo "setup_venv.sh: failed: $*" >&2
        exit 1
    fi
}

# Installs the given pip requirements ("name==version", extras allowed) unless
# every one is already installed (at that version when pinned).
ensure_packages() {
    if ! "$VENV/bin/python3" - "$@" >/dev/null 2>&1 <<'EOF'
import re, sys
from importlib.metadata import version, PackageNotFoundError
for spec in sys.argv[1:]:
    name = re.split(r"[\[=<>!~ ;]", spec, maxsplit=1)[0]
    try:
        have = version(name)
    except PackageNotFoundError:
        sys.exit(1)
    if "==" in spec and have != spec.split("==", 1)[1].strip():
        sys.exit(1)
EOF
    then
        run "$VENV/bin/python3" -m pip install --disable-pip-version-check -q "$@"
    fi
}

if [ ! -x "$VENV/bin/python3" ]; then
    run python3 -m venv "$VENV"
fi

# Independent MCAP/ROS 2 bag decoders (tests/bag_python.rs, scripts/decode_bag.py).
ensure_packages mcap==1.6.0 mcap-ros2-support==0.6.0 rosbags==0.11.9 numpy==2.4.6

# GNS-format TFRecord files written without TensorFlow (scripts/bag_to_gns.py,
# tests/import.rs).
ensure_packages tfrecord==1.14.6

# LagrangeBench-format HDF5 datasets (scripts/bag_to_lagrangebench.py,
# tests/import.rs).
ensure_packages h5py==3.16.0

# The Python package python/ (PyO3): maturin builds its wheel, pytest runs
# python/tests/ (tests/python.rs).
ensure_packages maturin==1.16.0 pytest==9.2.0

# ROS 2 Kilted from PyPI: rclpy with std/geometry/std_srvs messages, and what
# scripts/build_msgs.sh needs to build our interface package (see
# shared/ros-notes.md). Build-time packages are not pulled in by the others.
ensure_packages \
    "ros-kilted-rclpy[fastrtps]==9.1.2" ros-kilted-std-msgs==5.5.1 \
    ros-kilted-geometry-msgs==5.5.1 ros-kilted-std-srvs==5.5.1 \
    ros-kilted-diagnostic-msgs==5.5.1 ros-kilted-rosgraph-msgs==2.3.0 \
    ros-kilted-visualization-msgs==5.5.1 ros-kilted-sensor-msgs==5.5.1 \
    ros-kilted-ament-cmake==2.7.3 ros-kilted-ament-package==0.17.2 \
    ros-kilted-ament-cmake-ros-core==0.14.5 \
    ros-kilted-ament-cmake-include-directories==2.7.3 ros-kilted-ament-cmake-libraries==2.7.3 \
    ros-kilted-ament-cmake-gen-version-h==2.7.3 ros-kilted-ament-cmake-version==2.7.3 \
    ros-kilted-ament-cmake-python==2.7.3 ros-kilted-ament-cmake-target-dependencies==2.7.3 \
    ros-kilted-ament-cmake-test==2.7.3 ros-kilted-ament-cmake-export-definitions==2.7.3 \
    ros-kilted-ament-cmake-export-dependencies==2.7.3 \
    ros-kilted-ament-cmake-export-include-directories==2.7.3 \
    ros-kilted-ament-cmake-export-interfaces==2.7.3 ros-kilted-ament-cmake-export-libraries==2.7.3 \
    ros-kilted-ament-cmake-export-link-flags==2.7.3 ros-kilted-ament-cmake-export-targets==2.7.3 \
    ros-kilted-rosidl-default-generators==1.7.1 ros-kilted-rosidl-core-generators==0.3.1 \
    cmake==4.4.4 ninja==1.13.2 catkin-pkg==1.1.1

# colcon, to build this repository as a ROS 2 workspace (ros/: mcgnode_msgs
# and the mcgnode node package; tests/colcon.rs).
ensure_packages colcon-core==0.21.3 colcon-cmake==0.2.30 colcon-ros==0.5.0 \
    colcon-library-path==0.2.1 colcon-bash==0.5.0 colcon-package-information==0.4.1 \
    colcon-output==0.2.15

# The wheels' exported CMake files carry the build machine's Python paths:
# point them at this venv's (once; later runs find nothing to rewrite).
stale=$(grep -rl /opt/python/cp311-cp311 "$VENV"/share/*/cmake 2>/dev/null || true)
if [ -n "$stale" ]; then
    PYINC=$("$VENV/bin/python3" -c 'import sysconfig; print(sysconfig.get_path("include"))')
    NPINC=$("$VENV/bin/python3" -c 'import numpy; print(numpy.get_include())')
    # shellcheck disable=SC2086  # one path per word is what we want
    sed -i "s#/opt/python/cp311-cp311/include/python3.11#$PYINC#g; s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$NPINC#g" $stale
fi
