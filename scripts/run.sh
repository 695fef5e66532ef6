#!/usr/bin/env bash
# Set up the venv (scripts/setup.sh), then run the main job: sim_node on
# simple_spread through `vmas-ros sim`. Extra arguments go to `vmas-ros sim`.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
bash scripts/setup.sh

VENV="${VMAS_ROS_VENV:-.venv}"
case "$VENV" in /*) ;; *) VENV="$ROOT/$VENV" ;; esac

export RMW_IMPLEMENTATION=rmw_fastrtps_cpp  # the only RMW the venv has
export PATH="$VENV/bin:$PATH"
# The main job: sim_node on the default scenario (lidar on every agent). Extra
# arguments go to `vmas-ros sim` (e.g. --config config/waterfall.yaml, -p num_envs:=64).
exec "$VENV/bin/vmas-ros" sim --config "$ROOT/config/simple_spread.yaml" "$@"
