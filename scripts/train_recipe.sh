#!/usr/bin/env bash
# The training recipe of the shipped policy, one seed (models/pd_dqn_ocp.pt is its output for
# seed 1). Every demonstration and label comes from the optimal-control teacher
# mpc-fuel-reserve-state (the fuel teacher that keeps the layer's reserve and hands its last 2 s
# to its fallback on the state's time-to-go), from scratch, behind the runtime layer:
#   1. `ocp` preset: teacher-flown demonstrations, DQfD pre-training, interaction; 201,000
#      gradient updates, evaluated every 10,000;
#   2. `ocp-dagger` preset from stage 1's best.pt, under the `broad` dispersions: 500 teacher
#      episodes, then seven DAgger rounds (the initial network's and six more), each 500 new
#      episodes flown by the current network and labelled by the teacher, aggregated, 20k
#      pre-training updates after each; no interaction.
#      Both stages are budgeted by updates, not wall time, so a seed's file does not depend
#      on the machine's speed, load or torch thread count (another CPU may give other bits).
#      The recipe's policy is stage 2's best.pt. Wall time on two cores, alone: 59 min
#      (seed 3, docs/experiments/2026-12-02-three-seeds-and-teacher-campaign.md).
#
# --adapt (issue 68) adds a third stage to the ocp recipe:
#   3. `ocp-adapt` preset from stage 2's best.pt: the network also sees the thrust fraction its
#      layer counts on (widened with zero weights), behind the layer that counts on 80 % thrust
#      until the engine is measured, and the teacher mpc-fuel-reserve-state-lf; under `adapt`
#      (`broad` with weak engines and navigation biases): 500 teacher episodes and seven DAgger
#      rounds as stage 2, 140k updates (25 min). Its policy is DIR/stage3/final.pt (the
#      selection curve on `adapt` is flat within its noise; docs/experiments/
#      2026-12-05-adapt-student.md). --stage2 FILE starts it from FILE (models/pd_dqn_ocp.pt is
#      stage 2 of seed 1) and skips stages 1 and 2: `--adapt --stage2 models/pd_dqn_ocp.pt`
#      gives models/pd_dqn_adapt.pt. --adapt-teacher T labels stage 3 with teacher T instead:
#      mpc-fuel-reserve-state-lf-hold (its ZEM/ZEV fallback holds the pad down to the ground)
#      gives models/pd_dqn_hold.pt (docs/experiments/2026-12-06-hold-teacher-student.md).
#
# The demonstrator ablation (issue 32) keeps that recipe and its budget and changes only where
# the demonstrations come from (--demonstrator):
#   mpc-fuel-reserve-state  the recipe above (default);
#   mpc-fuel-reserve  the same two stages with the teacher handing over on its plan's clock
#                     (the recipe until 2026-12-02);
#   zemzev-vernier    the same two stages, ZEM/ZEV-vernier flying the demonstrations and labelling;
#   open-loop         the paper's 33 open-loop OCP trajectories (data/demos_7x7x3.npz): one `ocp`
#                     stage of the recipe's 341,000 gradient updates (201,000 + 7 x 20,000;
#                     open-loop plans cannot label the student's states);
#   none              no demonstrations: one `ocp` stage of 341,000 updates, interaction only.
# Their run directories default to runs/ablation_<demonstrator>__S.
#
# --teacher zemzev-vernier: the older 60 min recipe of the ZEM/ZEV lineage (models/pd_dqn_robust.md
# has the file that lineage shipped after ten hand-run rounds), three pd-train stages:
#   1. `best` preset from scratch (20 min);
#   2. fine-tune under `broad` from the zemzev-vernier teacher, behind the runtime layer, with
#      the landing bonus and the near-pad inputs (25 min, demonstrations included);
#   3. the same again from stage 2's best.pt (13.5 min). Its policy is stage 3's final.pt.
#
# A stage whose run directory already holds final.pt is skipped, and one that holds only a
# checkpoint is resumed (`pd-train --resume`, its wall time counted on), so an interrupted
# recipe goes on where it stopped.
set -euo pipefail

usage() {
    cat <<'EOF'
usage: scripts/train_recipe.sh [--seed S] [--out DIR] [--stage1 FILE.pt] [--paper-inputs]
                              [--adapt] [--stage2 FILE.pt] [--adapt-teacher T]
                              [--teacher zemzev-vernier|ocp] [--demonstrator D] [--threads N]
                              [--dry-run] [-h]

  --seed S         training seed of every stage (default 1)
  --out DIR        run directories DIR/stage1, DIR/stage2 (default runs/ocp__S;
                   --teacher zemzev-vernier: DIR/stage1..3, default runs/recipe__S)
  --stage1 FILE    skip stage 1 and start stage 2 from this policy
  --adapt          with --teacher ocp: a third stage, `ocp-adapt` (issue 68: the thrust input,
                   80 % until measured, weak engines and navigation biases); the policy is
                   DIR/stage3/final.pt
  --stage2 FILE    with --adapt: skip stages 1 and 2 and start stage 3 from this policy
  --adapt-teacher T  with --adapt: stage 3's teacher, mpc-fuel-reserve-state-lf (the
                   preset's, default) or mpc-fuel-reserve-state-lf-hold (models/pd_dqn_hold;
                   default DIR runs/adapt_T__S)
  --teacher T      ocp (default: the optimal-control teacher's recipe above, demonstrations
                   then aggregated DAgger rounds; the policy is DIR/stage2/best.pt) or
                   zemzev-vernier (the older ZEM/ZEV-lineage recipe; the policy is
                   DIR/stage3/final.pt)
  --paper-inputs   with --teacher zemzev-vernier, fine-tune without the near-pad inputs
                   (pd-train --near-pad): Eq. 21's 7 inputs only
  --demonstrator D with --teacher ocp, the ablation arm: mpc-fuel-reserve-state
                   (default), mpc-fuel-reserve, zemzev-vernier, open-loop (the paper's 33
                   trajectories) or none; the same recipe and budget (default DIR
                   runs/ablation_D__S)
  --threads N      torch threads of each stage (default 2: one seed on two cores; give 1 to
                   train two seeds side by side). With --teacher ocp the files are the same
                   either way (shortened runs of both stages, the whole stage 2, and the whole
                   recipe for seed 1: docs/experiments/2026-11-29-recipe-wall-time.md); 2
                   makes the updates 1.3-1.5x faster. The zemzev-vernier recipe stops on
                   wall time, so 2 gives it more updates: its five seeds were measured
                   with --threads 1
  --dry-run        print the pd-train command of each stage, one per line, and run nothing

The policy is DIR/stage2/best.pt (DIR/stage3/final.pt with --teacher zemzev-vernier);
evaluate it with
  pd-eval DIR/stage2/best.pt --dispersions standard --episodes 2000 --seed 0
EOF
}

seed=1
out=""
stage1=""
stage2=""
adapt=0
dry=0
threads=2
teacher=ocp
recipe_teacher=mpc-fuel-reserve-state  # what the ocp presets name (pd_core.dqn.config)
adapt_preset_teacher=mpc-fuel-reserve-state-lf  # what the ocp-adapt preset names
adapt_teacher=$adapt_preset_teacher
demonstrator=$recipe_teacher
near_pad=(--near-pad)
while [[ $# -gt 0 ]]; do
    case "$1" in
        -h | --help) usage; exit 0 ;;
        --seed) seed="${2:?--seed needs a value}"; shift 2 ;;
        --out) out="${2:?--out needs a directory}"; shift 2 ;;
        --stage1) stage1="${2:?--stage1 needs a policy file}"; shift 2 ;;
        --stage2) stage2="${2:?--stage2 needs a policy file}"; shift 2 ;;
        --adapt) adapt=1; shift ;;
        --adapt-teacher) adapt_teacher="${2:?--adapt-teacher needs a value}"; shift 2 ;;
        --paper-inputs) near_pad=(); shift ;;
        --teacher) teacher="${2:?--teacher needs zemzev-vernier or ocp}"; shift 2 ;;
        --demonstrator) demonstrator="${2:?--demonstrator needs a value}"; shift 2 ;;
        --threads) threads="${2:?--threads needs a value}"; shift 2 ;;
        --dry-run) dry=1; shift ;;
        *) echo "train_recipe.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
done
[[ "$threads" =~ ^[1-9][0-9]*$ ]] || { echo "train_recipe.sh: --threads must be a positive integer, got '$threads'" >&2; exit 2; }
[[ "$seed" =~ ^[0-9]+$ ]] || { echo "train_recipe.sh: --seed must be a non-negative integer, got '$seed'" >&2; exit 2; }
[[ -z "$stage1" || -f "$stage1" ]] || { echo "train_recipe.sh: --stage1 file not found: $stage1" >&2; exit 2; }
[[ -z "$stage2" || -f "$stage2" ]] || { echo "train_recipe.sh: --stage2 file not found: $stage2" >&2; exit 2; }
[[ -z "$stage2" ]] || ((adapt)) || { echo "train_recipe.sh: --stage2 needs --adapt" >&2; exit 2; }
((adapt == 0)) || [[ "$teacher" == ocp && "$demonstrator" == "$recipe_teacher" ]] || { echo "train_recipe.sh: --adapt needs --teacher ocp and the recipe's demonstrator" >&2; exit 2; }
case "$adapt_teacher" in
    mpc-fuel-reserve-state-lf | mpc-fuel-reserve-state-lf-hold) ;;
    *) echo "train_recipe.sh: --adapt-teacher must be mpc-fuel-reserve-state-lf or mpc-fuel-reserve-state-lf-hold, got '$adapt_teacher'" >&2; exit 2 ;;
esac
[[ "$adapt_teacher" == "$adapt_preset_teacher" ]] || ((adapt)) || { echo "train_recipe.sh: --adapt-teacher needs --adapt" >&2; exit 2; }
[[ "$teacher" == zemzev-vernier || "$teacher" == ocp ]] || { echo "train_recipe.sh: --teacher must be zemzev-vernier or ocp, got '$teacher'" >&2; exit 2; }
case "$demonstrator" in
    mpc-fuel-reserve-state | mpc-fuel-reserve | zemzev-vernier | open-loop | none) ;;
    *) echo "train_recipe.sh: --demonstrator must be mpc-fuel-reserve-state, mpc-fuel-reserve, zemzev-vernier, open-loop or none, got '$demonstrator'" >&2; exit 2 ;;
esac
[[ "$demonstrator" == "$recipe_teacher" || "$teacher" == ocp ]] || { echo "train_recipe.sh: --demonstrator needs --teacher ocp" >&2; exit 2; }
if [[ "$teacher" == ocp && "$demonstrator" != "$recipe_teacher" ]]; then
    out="${out:-runs/ablation_${demonstrator}__$seed}"
elif [[ "$teacher" == ocp && "$adapt_teacher" != "$adapt_preset_teacher" ]]; then
    out="${out:-runs/adapt_${adapt_teacher}__$seed}"
elif [[ "$teacher" == ocp ]]; then
    out="${out:-runs/ocp__$seed}"
else
    out="${out:-runs/recipe__$seed}"
fi

FINE_TUNE=(--preset robust --controller zemzev-vernier --precision-bonus 10
    --recovery-failed-share 0.5 --layer --dispersions broad "${near_pad[@]}")
start=$SECONDS

stage() {  # stage NAME ARGS...: run pd-train unless NAME already finished
    local name=$1
    shift
    local cmd=(pd-train "$@" --seed "$seed" --torch-threads "$threads" --run-dir "$out/$name")
    if ((dry)); then
        printf '%q ' "${cmd[@]}"  # quoted, so an empty value (--controller '') survives
        echo
        return
    fi
    if [[ -f "$out/$name/final.pt" ]]; then
        echo "== $name: $out/$name/final.pt exists, skipped"
        return
    fi
    if [[ -f "$out/$name/checkpoint.pt" ]]; then
        cmd=(pd-train --resume "$out/$name" --torch-threads "$threads")
        echo "== $name: resuming from $out/$name/checkpoint.pt"
    fi
    echo "== $name: ${cmd[*]}"
    local t0=$SECONDS
    "${cmd[@]}"
    echo "== $name: $(((SECONDS - t0) / 60)) min $(((SECONDS - t0) % 60)) s"
}

if [[ "$teacher" == ocp && ( "$demonstrator" == open-loop || "$demonstrator" == none ) ]]; then
    # no closed-loop teacher to label with: the whole update budget (stage 1's 201,000 and
    # stage 2's 7 x 20,000) in one stage, evaluated like stage 1
    if [[ "$demonstrator" == open-loop ]]; then
        arm=(--controller "" --controller-demo-episodes 0 --demos data/demos_7x7x3.npz)
    else
        arm=(--controller "" --controller-demo-episodes 0 --batch-demo 0 --pretrain-updates 0 --margin 0)
    fi
    stage stage1 --preset ocp "${arm[@]}" --max-updates 341000
    ((dry)) || echo "== recipe done in $(((SECONDS - start) / 60)) min: $out/stage1/best.pt"
    exit 0
fi
if [[ "$teacher" == ocp ]]; then
    arm=()
    [[ "$demonstrator" != "$recipe_teacher" ]] && arm=(--controller "$demonstrator")
    if [[ -z "$stage2" ]]; then
        if [[ -z "$stage1" ]]; then
            stage stage1 --preset ocp "${arm[@]}"
            stage1="$out/stage1/best.pt"
        fi
        stage stage2 --preset ocp-dagger "${arm[@]}" --init-policy "$stage1"
        stage2="$out/stage2/best.pt"
    fi
    if ((adapt)); then
        arm3=()
        [[ "$adapt_teacher" != "$adapt_preset_teacher" ]] && arm3=(--controller "$adapt_teacher")
        stage stage3 --preset ocp-adapt "${arm3[@]}" --init-policy "$stage2"
        ((dry)) || echo "== recipe done in $(((SECONDS - start) / 60)) min: $out/stage3/final.pt"
        exit 0
    fi
    ((dry)) || echo "== recipe done in $(((SECONDS - start) / 60)) min: $out/stage2/best.pt"
    exit 0
fi
if [[ -z "$stage1" ]]; then
    stage stage1 --preset best --max-minutes 20
    stage1="$out/stage1/best.pt"
fi
stage stage2 "${FINE_TUNE[@]}" --init-policy "$stage1" --max-minutes 25
stage stage3 "${FINE_TUNE[@]}" --init-policy "$out/stage2/best.pt" --max-minutes 13.5
((dry)) || echo "== recipe done in $(((SECONDS - start) / 60)) min: $out/stage3/final.pt"
