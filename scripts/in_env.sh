#!/usr/bin/env bash
# Run one command inside the project's environment:   scripts/in_env.sh CMD [ARGS...]
# (sources env.sh: .venv + ros2_ws/install/setup.bash + RMW/discovery settings; see env.sh).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [[ $# -eq 0 ]]; then
    echo "usage: scripts/in_env.sh CMD [ARGS...]" >&2
    exit 2
fi
# shellcheck disable=SC1091
source "$ROOT/env.sh"
exec "$@"
