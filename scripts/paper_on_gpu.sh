#!/usr/bin/env bash
# The paper's Agents 1 and 2 (Sec. 3.2, Table 2) at the paper's own update ratio, one gradient
# update per env transition, trained together on a CUDA GPU inside a fixed wall budget.
#
# Runs in the repository root with the package on PYTHONPATH (no colcon build needed). In order:
#   0. wheels carried in .whl/ (gymnasium, highspy: the GPU machine has no PyPI) into /tmp/site;
#   1. the machine: GPU, torch, numpy, numba;
#   2. the CUDA tests of tests/unit/dqn/test_dqn_device.py and tests/unit/dqn/test_device_loop.py (the
#      graph block agrees with the eager block, and with the CPU), which skip without a GPU;
#   3. bench/train_speed.py --device-loop --gpu-only: updates/s of the plain loop, the graph
#      path and the device loop for K in {1, 8, 32, 128}, one and four agents together;
#   4. pd-train --preset paper-agent1 --agents <AGENTS> --loop device --num-envs 16
#      --updates-per-step 16 --device auto: every agent in one device loop (16 envs each, their
#      16 updates one CUDA graph), with the wall time left (--max-minutes), into OUT/run;
#   5. OUT/runs.tgz: the run folders (policies, CSV logs, curves), to bring back.
# Table 2 unchanged but for evaluating every 500,000 updates (not a Table 2 setting).
set -euo pipefail

usage="usage: scripts/paper_on_gpu.sh [--budget-s S] [--out DIR] [--preset P] [--seed N]
                              [--agents LIST] [--smoke] [--skip-checks] [--dry-run]
  --budget-s S   wall seconds for the whole script (default 540); training gets what is left
  --out DIR      where logs, the run folders and runs.tgz go (default runs/paper_gpu)
  --preset P     the first agent: paper-agent1 (default) or paper-agent2
  --seed N       the first agent's seed (default 1)
  --agents LIST  more agents trained together, preset:seed pairs (default paper-agent2:1;
                 e.g. paper-agent2:1,paper-agent1:2,paper-agent1:3; '' for Agent 1 alone)
  --smoke        steps 0-3, then a 30 s training: a first call that measures the machine
  --skip-checks  skip steps 2 and 3
  --dry-run      print step 4's pd-train command (with the whole budget less 40 s) and exit"
budget=540
out=runs/paper_gpu
first=paper-agent1
seed=1
agents=paper-agent2:1
checks=1
smoke=0
dry=0
margin_s=40 # for the run's last evaluations, saves and curves after --max-minutes
while [[ $# -gt 0 ]]; do
    case "$1" in
        --budget-s) budget="$2"; shift 2 ;;
        --out) out="$2"; shift 2 ;;
        --preset) first="$2"; shift 2 ;;
        --seed) seed="$2"; shift 2 ;;
        --agents) agents="$2"; shift 2 ;;
        --smoke) smoke=1; shift ;;
        --skip-checks) checks=0; shift ;;
        --dry-run) dry=1; shift ;;
        -h|--help) echo "$usage"; exit 0 ;;
        *) echo "paper_on_gpu.sh: unknown argument $1" >&2; echo "$usage" >&2; exit 2 ;;
    esac
done

train_args=(--preset "$first" --seed "$seed" --num-envs 16 --updates-per-step 16
    --loop device --device auto --eval-every-updates 500000 --progress false
    --run-dir "$out/run")
[[ -n $agents ]] && train_args+=(--agents "$agents")
minutes_of() { awk -v s="$1" 'BEGIN { printf "%.2f", s / 60 }'; }
if [[ $dry == 1 ]]; then
    echo pd-train "${train_args[@]}" --max-minutes "$(minutes_of $((budget - margin_s)))"
    exit 0
fi

root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
py="${PYTHON:-python3}"
export PYTHONUNBUFFERED=1
if [[ -d .whl ]] && ! "$py" -c "import gymnasium, highspy" 2>/dev/null; then
    echo "== 0. wheels from .whl"
    "$py" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl
    export PYTHONPATH="/tmp/site${PYTHONPATH:+:$PYTHONPATH}"
fi
export PYTHONPATH="$root/pd_core${PYTHONPATH:+:$PYTHONPATH}"
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
    "$py" -m pytest -q -p no:cacheprovider -k "cuda or gpu" tests/unit/dqn/test_dqn_device.py \
        tests/unit/dqn/test_device_loop.py 2>&1 | tee "$out/tests.log" ||
        echo "paper_on_gpu.sh: the CUDA tests failed; training anyway"
    echo "== 3. bench/train_speed.py --device-loop"
    "$py" bench/train_speed.py --device-loop --gpu-only --seconds 1 --agents 1 4 2>&1 |
        tee "$out/train_speed.log" || echo "paper_on_gpu.sh: the bench failed; training anyway"
fi

left=$((budget - (SECONDS - t0) - margin_s))
[[ $smoke == 1 ]] && left=30
if [[ $left -lt 60 && $smoke == 0 ]]; then
    echo "paper_on_gpu.sh: only ${left} s left for training; stopping" >&2
    exit 1
fi
minutes=$(minutes_of "$left")
echo "== 4. pd-train: $first (seed $seed) and ${agents:-no other agent}, one update per" \
    "transition, ${minutes} min"
"$py" -m pd_core.cli.train "${train_args[@]}" --max-minutes "$minutes" 2>&1 |
    tee "$out/train.log"
echo "== 5. $out/runs.tgz"
tar czf "$out/runs.tgz" -C "$out" run
echo "== done in $((SECONDS - t0)) s"
