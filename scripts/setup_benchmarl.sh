#!/usr/bin/env bash
# A venv of its own for BenchMARL, beside the project's: BenchMARL 1.5 pins an
# older torchrl (< 0.12) than vmas_ros's training extra (0.14), so the two
# cannot share one environment. Idempotent: a second run with nothing changed
# only checks the venv.
#
#   VMAS_ROS_BENCHMARL_VENV  venv location (default: <repo>/.venv-benchmarl)
#   VMAS_ROS_PYTHON          interpreter used to create it (default: python3.11, else python3)
#
# Inside it: torch==2.13.0 (pinned first, as in setup.sh: an unpinned torch
# pulls a CUDA build), benchmarl, vmas_ros (editable, with the gym extra
# that install_as_vmas() needs for TorchRL's VMAS spaces), and onnx for
# vmas-ros export --from-benchmarl.
set -euo pipefail

TORCH_PIN="torch==2.13.0"
BENCHMARL_PIN="benchmarl==1.5.2"
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="${VMAS_ROS_BENCHMARL_VENV:-.venv-benchmarl}"
case "$VENV" in /*) ;; *) VENV="$ROOT/$VENV" ;; esac
PY="$VENV/bin/python"
export PIP_NO_INPUT=1 PIP_DISABLE_PIP_VERSION_CHECK=1

log() { echo "setup_benchmarl.sh: $*"; }
die() { echo "setup_benchmarl.sh: error: $*" >&2; exit 1; }
. "$ROOT/scripts/venv_lib.sh"  # pip_q, base_python

if [ ! -x "$PY" ]; then
    base="$(base_python)"
    "$base" -m venv --clear "$VENV"
    log "venv $VENV: created"
fi

stamp_file="$VENV/.vmas_ros_benchmarl_stamp"
stamp="$(cat setup.py scripts/setup_benchmarl.sh scripts/venv_lib.sh | "$PY" -c 'import hashlib, sys; print(hashlib.sha256(sys.stdin.buffer.read()).hexdigest())')"
if [ -f "$stamp_file" ] && [ "$(cat "$stamp_file")" = "$stamp" ] \
    && "$PY" -c 'import benchmarl, vmas_ros, onnx, onnxruntime' 2>/dev/null; then
    log "packages: up to date"
else
    pip_q install "$TORCH_PIN"
    pip_q install "$BENCHMARL_PIN" "$TORCH_PIN"
    pip_q install -e ".[gym]" "$TORCH_PIN"
    # vmas-ros export --from-benchmarl converts the policy here, with torch.onnx
    pip_q install onnx onnxscript onnxruntime "$TORCH_PIN"
    echo "$stamp" > "$stamp_file"
    log "installed: $("$PY" -c 'import importlib.metadata as m; print(", ".join(f"{p} {m.version(p)}" for p in ("torch", "torchrl", "benchmarl", "vmas_ros")))')"
fi
log "done; run BenchMARL with: $PY (call vmas_ros.install_as_vmas() first)"
