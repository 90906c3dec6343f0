#!/usr/bin/env bash
# `ros2 run PACKAGE EXECUTABLE [ARGS...]` for this machine, which has no ros2 CLI: runs
# ros2_ws/install/PACKAGE/lib/PACKAGE/EXECUTABLE (where colcon installs ament_python entry points)
# inside the project's environment. Example: scripts/ros2_run.sh pd_sim_node sim_node --ros-args ...
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [[ $# -lt 2 ]]; then
    echo "usage: scripts/ros2_run.sh PACKAGE EXECUTABLE [ARGS...]" >&2
    exit 2
fi
pkg="$1"
exe="$2"
shift 2
# shellcheck disable=SC1091
source "$ROOT/env.sh"
IFS=: read -r -a prefixes <<<"${AMENT_PREFIX_PATH:-}"
for prefix in "${prefixes[@]}"; do
    if [[ -x $prefix/lib/$pkg/$exe ]]; then
        exec "$prefix/lib/$pkg/$exe" "$@"
    fi
done
echo "ros2_run.sh: no executable '$exe' in package '$pkg' (looked in \$AMENT_PREFIX_PATH/lib/$pkg/)" >&2
exit 1
