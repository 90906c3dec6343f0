# shellcheck shell=bash
# Put this shell in the project's environment:   source env.sh
#
# - activates .venv/ (ROS 2 Kilted wheels, torch, pd_core installed editable, pd-* commands);
# - adds the venv to AMENT_PREFIX_PATH / CMAKE_PREFIX_PATH (the wheels install their ament index
#   and CMake configs there; the ROS wheels ship no setup.bash of their own to chain to);
# - sources ros2_ws/install/setup.bash (pd_interfaces, pd_core and the node packages);
# - selects FastDDS and keeps discovery on loopback.
# Made by `make setup`; safe to source more than once. Needs bash (or zsh).

_pd_root="$(cd "$(dirname "${BASH_SOURCE[0]:-$0}")" && pwd)"

if [ ! -x "$_pd_root/.venv/bin/python" ] || [ ! -f "$_pd_root/ros2_ws/install/setup.bash" ]; then
    echo "env.sh: the environment is not built yet; run 'make setup' in $_pd_root" >&2
    unset _pd_root
    return 1 2>/dev/null || exit 1
fi

# shellcheck disable=SC1091
. "$_pd_root/.venv/bin/activate"

_pd_prepend() { # _pd_prepend VAR DIR: put DIR first in VAR unless it is already there
    case ":${!1:-}:" in
        *":$2:"*) ;;
        *) export "$1=$2${!1:+:${!1}}" ;;
    esac
}
_pd_prepend AMENT_PREFIX_PATH "$_pd_root/.venv"
_pd_prepend CMAKE_PREFIX_PATH "$_pd_root/.venv"

# colcon's setup.bash reads unset variables; do not let a caller's `set -u` trip on them.
case $- in *u*) _pd_had_u=1; set +u ;; *) _pd_had_u= ;; esac
# shellcheck disable=SC1091
. "$_pd_root/ros2_ws/install/setup.bash"
[ -n "$_pd_had_u" ] && set -u

# The nodes' ament_python entry points (what `ros2 run` would find) on PATH, so
# `pd_sim_node --ros-args ...` works here without the ros2 CLI.
for _pd_d in "$_pd_root"/ros2_ws/install/pd_*/lib/pd_*; do
    [ -d "$_pd_d" ] && _pd_prepend PATH "$_pd_d"
done
unset _pd_d
export PD_ROOT="$_pd_root"
# One BLAS/OpenMP thread per process: on 2 cores shared by several nodes and tests, threaded BLAS
# makes the OCP's small products ~100x slower; torch in pd-train sets its own thread count.
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}"
export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"
# DDS discovery stays on this machine (ROS_LOCALHOST_ONLY is deprecated since Jazzy).
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
unset ROS_LOCALHOST_ONLY
# ROS_DOMAIN_ID is left as the caller has it (default 0). The integration tests pick their own
# free domain (tests/integration/conftest.py), so they never hear a demo running beside them.

unset _pd_root _pd_had_u
unset -f _pd_prepend
