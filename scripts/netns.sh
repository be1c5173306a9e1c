#!/usr/bin/env bash
# Runs a command in a private network namespace that holds only loopback (with a
# multicast route, which DDS discovery needs), so ROS 2 / DDS traffic can never
# leave this machine. Everything that starts DDS (the node, rclpy scripts) goes
# through this script; processes that must talk to each other run under one call:
#
#     scripts/netns.sh bash -c 'mcgnode serve --params p.yaml & python3 scripts/ros/echo.py /predicted_trajectory'
#
# ROS_DOMAIN_ID is taken from the environment, or a random one (1..100) is picked
# and exported. As root this uses `unshare -n`, otherwise `unshare -rn`.
#
# The command also gets its own pid namespace in which it is pid 1: when it exits
# (or this script is killed), the kernel kills every process it left behind, so no
# `mcgnode serve` or rclpy driver outlives the test that started it.
set -euo pipefail
if [ $# -eq 0 ] || [ "$1" = "-h" ] || [ "$1" = "--help" ]; then
    sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//'
    echo "usage: scripts/netns.sh COMMAND [ARGS...]"
    [ $# -eq 0 ] && exit 2 || exit 0
fi

if [ "${MCGNODE_NETNS_INSIDE:-}" != 1 ] || [ "$$" != 1 ]; then
    if [ "$(id -u)" = 0 ]; then unshare=(unshare -n); else unshare=(unshare -rn); fi
    # --kill-child: SIGKILL to the namespace's pid 1 if unshare itself dies;
    # --mount-proc: /proc (and pgrep, /proc/self) shows this pid namespace.
    unshare+=(--pid --fork --kill-child --mount-proc)
    # Pid 1 with the marker set proves we are the re-executed script.
    export MCGNODE_NETNS_INSIDE=1
    exec "${unshare[@]}" bash "$0" "$@"
fi
unset MCGNODE_NETNS_INSIDE

# Refuse to run if anything but loopback is visible (unshare did not isolate us).
if ip -o link show | awk -F': ' '{print $2}' | grep -qv '^lo$'; then
    echo "netns.sh: interfaces other than lo are visible; refusing to start DDS" >&2
    exit 1
fi
ip link set lo up
ip link set lo multicast on
ip route add 224.0.0.0/4 dev lo

if [ -z "${ROS_DOMAIN_ID:-}" ]; then
    ROS_DOMAIN_ID=$(( (RANDOM % 100) + 1 ))
    echo "netns.sh: ROS_DOMAIN_ID=$ROS_DOMAIN_ID" >&2
fi
export ROS_DOMAIN_ID ROS_DISTRO=kilted
exec "$@"
