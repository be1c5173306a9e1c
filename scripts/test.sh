#!/usr/bin/env bash
# The whole test suite, from a fresh clone: provisions the Python venv (rclpy and
# independent MCAP readers from PyPI), builds the ROS 2 interface package from
# msg/, then runs every Rust test (unit, integration, ROS 2 against real rclpy)
# in release mode. Extra arguments go to `cargo test`.
set -euo pipefail
cd "$(dirname "$0")/.."
echo "== provisioning .venv (rclpy, mcap readers)"
scripts/setup_venv.sh
echo "== building the mcgnode_msgs interface package"
scripts/build_msgs.sh >/dev/null
echo "== cargo test --release"
cargo test --release "$@"
