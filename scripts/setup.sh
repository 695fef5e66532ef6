#!/usr/bin/env bash
# Set up (or check) the project's virtual environment. Idempotent: a second
# run with nothing changed only checks the venv and returns in about a second.
#
#   VMAS_ROS_VENV   venv location (default: <repo>/.venv)
#   VMAS_ROS_PYTHON interpreter used to create the venv (default: python3.11,
#                   else python3; needs Python >= 3.10)
#
# torch is installed first and pinned: `torch==2.13.0` is a CPU build that the
# project's machines have cached, while an unpinned torch (directly or through
# another package's requirement) downloads a multi-GB CUDA build.
set -euo pipefail

TORCH_PIN="torch==2.13.0"
EXTRAS="ros,record,foxglove,play,train,rllib,gym,test"

start=$SECONDS
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="${VMAS_ROS_VENV:-.venv}"
case "$VENV" in /*) ;; *) VENV="$ROOT/$VENV" ;; esac
PY="$VENV/bin/python"

export PIP_NO_INPUT=1 PIP_DISABLE_PIP_VERSION_CHECK=1

log() { echo "setup.sh: $*"; }
die() { echo "setup.sh: error: $*" >&2; exit 1; }

. "$ROOT/scripts/venv_lib.sh"  # pip_q, base_python

# 1. the venv
if [ -x "$PY" ] && "$PY" -c 'import sys; assert sys.version_info >= (3, 10)' 2>/dev/null; then
    log "venv $VENV: present"
else
    base="$(base_python)"
    if [ -e "$VENV" ] && [ ! -f "$VENV/pyvenv.cfg" ] && [ -n "$(ls -A "$VENV" 2>/dev/null)" ]; then
        die "$VENV exists and is not a venv; remove it or set VMAS_ROS_VENV"
    fi
    "$base" -m venv --clear "$VENV"
    log "venv $VENV: created with $("$PY" --version 2>&1)"
fi

# 2. everything else, unless the last successful run installed the same thing
# into this venv from this checkout (stamp = hash of the packaging files).
stamp_file="$VENV/.vmas_ros_setup_stamp"
stamp="$(cat setup.py setup.cfg package.xml scripts/setup.sh scripts/venv_lib.sh | "$PY" -c '
import hashlib, sys
h = hashlib.sha256(sys.stdin.buffer.read())
h.update(sys.argv[1].encode())
print(h.hexdigest())' "$ROOT")"

installed_ok() {
    "$PY" - "$ROOT" "${TORCH_PIN#torch==}" <<'PYEOF' 2>/dev/null
import importlib.metadata as md, importlib.util, os, sys
root, torch_version = sys.argv[1], sys.argv[2]
assert md.version("torch").split("+")[0] == torch_version
md.version("vmas_ros")
spec = importlib.util.find_spec("vmas_ros")
assert spec and spec.origin and os.path.realpath(spec.origin).startswith(os.path.realpath(root) + os.sep)
PYEOF
}

if [ -f "$stamp_file" ] && [ "$(cat "$stamp_file")" = "$stamp" ] && installed_ok; then
    log "packages: up to date (torch ${TORCH_PIN#torch==}, vmas_ros editable [$EXTRAS])"
else
    rm -f "$stamp_file"
    t=$SECONDS
    pip_q install "$TORCH_PIN"
    log "torch: $("$PY" -c 'import importlib.metadata as m; print(m.version("torch"))') ($((SECONDS - t)) s)"
    t=$SECONDS
    # An editable wheel (PEP 660), so the console scripts go to the venv's bin/:
    # the legacy `setup.py develop`, which pip < 25 picks for a setup.py-only
    # project when setuptools is installed, would follow setup.cfg's script_dir.
    # pip >= 26 has no --use-pep517 flag (it always builds that way).
    pep517=()
    if "$PY" -m pip install --help 2>/dev/null | grep -q -- '--use-pep517'; then pep517=(--use-pep517); fi
    pip_q install "${pep517[@]}" -e ".[$EXTRAS]" "$TORCH_PIN"
    installed_ok || die "vmas_ros is not importable from $ROOT after pip install -e"
    echo "$stamp" > "$stamp_file"
    log "vmas_ros: editable install with extras [$EXTRAS] ($((SECONDS - t)) s)"
fi

log "done in $((SECONDS - start)) s; activate with: source ${VENV#"$ROOT/"}/bin/activate"
