#!/usr/bin/env bash
# One command on a fresh machine: set up, then run the live simulator -> estimator demo
# (two ROS 2 nodes over DDS, embedded default parameters) and print the tracking error.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$root/scripts/setup_env.sh"
exec "$root/.venv/bin/python" -m ipmc_sensor_ros.nodes.demo "$@"
