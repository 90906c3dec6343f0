#!/usr/bin/env bash
# The paper's Agent 1 (Sec. 3.2, Table 2) at the paper's own update ratio, one gradient update per
# env transition, on a CUDA GPU, inside a fixed wall budget.
#
# Runs in the repository root with the package on PYTHONPATH (no colcon build needed). In order:
#   1. the machine: GPU, torch, numpy, numba;
#   2. the CUDA tests (tests/unit/test_dqn_device.py: the graph step agrees with the eager step,
#      a cuda run resumes on the cpu), which skip without a GPU;
#   3. bench/train_speed.py: updates/s of our update beside a plain-torch loop on every device;
#   4. pd-train --preset paper-agent1 --num-envs 16 --updates-per-step 16 --device auto, with
#      the wall time left (--max-minutes), into OUT/run.
# Step 4 is the paper's ratio: 16 envs stepped together, then their 16 updates. One env per step
# (the paper's literal loop) costs ~270 us of host work per transition (bench/train_speed.py
# section 2), which 3 M transitions cannot afford.
set -euo pipefail

usage="usage: scripts/paper_on_gpu.sh [--budget-s S] [--out DIR] [--seed N] [--skip-checks] [--dry-run]
  --budget-s S   wall seconds for the whole script (default 540); training gets what is left
  --out DIR      where logs and the run folder go (default runs/paper_gpu)
  --seed N       training seed (default 1)
  --skip-checks  skip steps 2 and 3
  --dry-run      print step 4's pd-train command (with the whole budget less 40 s) and exit"
budget=540
out=runs/paper_gpu
seed=1
checks=1
dry=0
margin_s=40 # for the run's last evaluation and save after --max-minutes
while [[ $# -gt 0 ]]; do
    case "$1" in
        --budget-s) budget="$2"; shift 2 ;;
        --out) out="$2"; shift 2 ;;
        --seed) seed="$2"; shift 2 ;;
        --skip-checks) checks=0; shift ;;
        --dry-run) dry=1; shift ;;
        -h|--help) echo "$usage"; exit 0 ;;
        *) echo "paper_on_gpu.sh: unknown argument $1" >&2; echo "$usage" >&2; exit 2 ;;
    esac
done

train_args=(--preset paper-agent1 --seed "$seed" --num-envs 16 --updates-per-step 16
    --device auto --progress false --run-dir "$out/run")
minutes_of() { awk -v s="$1" 'BEGIN { printf "%.2f", s / 60 }'; }
if [[ $dry == 1 ]]; then
    echo pd-train "${train_args[@]}" --max-minutes "$(minutes_of $((budget - margin_s)))"
    exit 0
fi

root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
export PYTHONPATH="$root/ros2_ws/src/pd_core${PYTHONPATH:+:$PYTHONPATH}"
export PYTHONUNBUFFERED=1
py="${PYTHON:-python3}"
mkdir -p "$out"
t0=$SECONDS

echo "== 1. machine"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader 2>/dev/null ||
    echo "no nvidia-smi"
"$py" -c "import sys, torch, numpy, numba; print('python', sys.version.split()[0], '| torch',
torch.__version__, '| cuda', torch.cuda.is_available(), '| numpy', numpy.__version__,
'| numba', numba.__version__, '| cpus', __import__('os').cpu_count())"

if [[ $checks == 1 ]]; then
    echo "== 2. CUDA tests"
    "$py" -m pytest -q -p no:cacheprovider tests/unit/test_dqn_device.py 2>&1 | tee "$out/tests.log" ||
        echo "paper_on_gpu.sh: the CUDA tests failed; training anyway"
    echo "== 3. bench/train_speed.py"
    "$py" bench/train_speed.py --seconds 2 2>&1 | tee "$out/train_speed.log" ||
        echo "paper_on_gpu.sh: bench/train_speed.py failed; training anyway"
fi

left=$((budget - (SECONDS - t0) - margin_s))
if [[ $left -lt 60 ]]; then
    echo "paper_on_gpu.sh: only ${left} s left for training; stopping" >&2
    exit 1
fi
minutes=$(minutes_of "$left")
echo "== 4. pd-train paper-agent1 at one update per transition, ${minutes} min"
"$py" -m pd_core.cli.train "${train_args[@]}" --max-minutes "$minutes" 2>&1 | tee "$out/train.log"
echo "== done in $((SECONDS - t0)) s"
