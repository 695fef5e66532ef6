#!/usr/bin/env bash
# Set up the venv (scripts/setup.sh), then run the test suite in it.
# Extra arguments go to pytest, e.g. `bash scripts/test.sh test/test_package.py -x`.
# With no file arguments pytest collects `test/` (testpaths in pytest.ini).
# `--quick` first: the contributors' tier (engine, scenario registry, env API, policies and the
# import graph, without the slow and ROS tests), about two minutes; CI runs everything.
# With no arguments: the tests that can share the machine on two workers, then the
# `serial` ones alone (VMAS_ROS_TEST_WORKERS sets the workers; 1: one plain run).
# Exits with pytest's exit code (the worse of the two parts).
set -euo pipefail

QUICK=()
if [ "${1:-}" = "--quick" ]; then
  shift
  QUICK=(-m "not slow and not ros" test/simulator test/envs test/policy test/scenarios/test_registry.py
         test/test_import_graph.py --ignore=test/simulator/test_properties.py)
fi

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
bash scripts/setup.sh

VENV="${VMAS_ROS_VENV:-.venv}"
case "$VENV" in /*) ;; *) VENV="$ROOT/$VENV" ;; esac

# A DDS domain of its own per session, so parallel runs don't see each other, and
# discovery on this machine only: no test ever talks to another host.
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( RANDOM % 100 + 1 ))}"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
# eager physics for the envs the tests build (the default mode compiles each; see test/conftest.py)
export VMAS_ROS_COMPILE="${VMAS_ROS_COMPILE:-0}"
# Ray on loopback only, and no usage reports to Ray's servers (the Ray cluster tests)
export RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0
export RAY_USAGE_STATS_ENABLED=0
export PATH="$VENV/bin:$PATH"
echo "test.sh: ROS_DOMAIN_ID=$ROS_DOMAIN_ID ROS_AUTOMATIC_DISCOVERY_RANGE=$ROS_AUTOMATIC_DISCOVERY_RANGE" \
     "RMW_IMPLEMENTATION=$RMW_IMPLEMENTATION"

PYTEST=("$VENV/bin/python" -m pytest -q -ra --timeout=600 -p no:cacheprovider)
# Workers for the parallel part (pytest-xdist; each in a DDS domain of its own, see
# test/conftest.py). 1, or any file or option given, runs one plain pytest instead.
WORKERS="${VMAS_ROS_TEST_WORKERS:-2}"
XDIST=()
# files in test/conftest.py's order (the long ones first), not xdist's
[ "$WORKERS" -gt 1 ] && XDIST=(-n "$WORKERS" --dist loadfile --no-loadscope-reorder)
if [ ${#QUICK[@]} -gt 0 ]; then
  exec "${PYTEST[@]}" ${XDIST[@]+"${XDIST[@]}"} "${QUICK[@]}" "$@"
fi
if [ $# -gt 0 ] || [ "$WORKERS" -le 1 ]; then
  exec "${PYTEST[@]}" "$@"
fi

# The whole suite: BenchMARL's venv first (set-up, as the project's venv above: the
# BenchMARL tests need it, and their fixture only checks it then); the tests that may
# share the machine on all workers, a file per worker at a time (module fixtures stay
# shared); then the `serial` tests (they measure time, rates or load) alone. Both
# parts always run; exit code: the worse.
start=$SECONDS
if bash scripts/setup_benchmarl.sh; then
  echo "test.sh: BenchMARL's venv ready in $(( SECONDS - start )) s"
else  # the rest still runs; the BenchMARL tests run the set-up again and say why it fails
  echo "test.sh: BenchMARL's venv failed to set up (see above)"
fi
parallel=0 serial=0
start=$SECONDS
"${PYTEST[@]}" "${XDIST[@]}" -m "not serial" --durations=15 || parallel=$?
echo "test.sh: parallel part (-n $WORKERS): exit $parallel in $(( SECONDS - start )) s"
start=$SECONDS
"${PYTEST[@]}" -m serial --durations=10 || serial=$?
[ "$serial" -eq 5 ] && serial=0  # no serial test collected
echo "test.sh: serial part: exit $serial in $(( SECONDS - start )) s"
exit $(( parallel > serial ? parallel : serial ))
