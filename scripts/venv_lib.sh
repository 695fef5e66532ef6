# Shell helpers shared by the set-up scripts (setup.sh, setup_benchmarl.sh).
# Source it after defining PY (the venv's python) and die (print and exit).

# pip, quietly: drop its "Location ... is ignored" warnings (local index
# mirrors that lack a package), keep everything else, return pip's status.
pip_q() {
    local rc
    set +e
    "$PY" -m pip -q "$@" 2>&1 | grep -v -E "^WARNING: Location '.*' is ignored" >&2
    rc=${PIPESTATUS[0]}
    set -e
    return "$rc"
}

# The interpreter to create a venv with: $VMAS_ROS_PYTHON, else python3.11,
# else python3; it must be Python >= 3.10.
base_python() {
    local base="${VMAS_ROS_PYTHON:-}"
    if [ -z "$base" ]; then
        for cand in python3.11 python3; do
            if command -v "$cand" >/dev/null 2>&1; then base="$cand"; break; fi
        done
    fi
    [ -n "$base" ] || die "no python3.11 or python3 on PATH"
    "$base" -c 'import sys; assert sys.version_info >= (3, 10)' 2>/dev/null \
        || die "$base is older than Python 3.10"
    echo "$base"
}
