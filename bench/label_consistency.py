"""Are the teacher's labels a function of the state, and which labels can a network fit? (issue 32)

A student file flies behind its runtime layer (`pd_core.demonstrations.dagger.student_labels`)
and the teacher labels its states in shadow, re-planning warm along the flight ("warm": the
DAgger labels, which carry the plan's time-to-go and basis from state to state). The same
states are then labelled "cold": `MPCController.first_action`, a free-final-time solve from the
state alone, a function of the state by construction. The run prints

1. how often the two labels are the same action, and the same level on each axis;
2. for each label set, a Q-network of the policy's shape (7 scaled inputs and the near-pad
   features, 300-200-300 tanh, 147 outputs) fitted by cross-entropy on the first 80 % of the
   states (whole episodes) and scored on the rest: held-out accuracy, per axis and in levels.

    python bench/label_consistency.py [--policy models/pd_dqn_ocp.pt] [--teacher mpc-fuel-reserve]
        [--episodes 50] [--seed 5000] [--dispersions ""] [--steps 3000] [--workers 2] [--fit-seed 0]

Cold labels cost one free-final-time solve each (about 50 ms): 50 episodes, ~12k states, take
about 5 min on 2 cores.
"""

from __future__ import annotations

import argparse
import time
from multiprocessing import get_context

import numpy as np
import torch

from pd_core.actions import DEFAULT_ACTIONS
from pd_core.demonstrations.dagger import student_labels
from pd_core.dqn.network import QNetwork
from pd_core.state import scale_state
from pd_core.teachers.registry import make_controller


def cold_labels(args: tuple[str, np.ndarray]) -> np.ndarray:
    """The teacher's action from each state with no plan before it (a cold solve)."""
    teacher, states = args
    ctl = make_controller(teacher)
    return np.array([ctl.first_action(s) for s in states], dtype=np.int64)


def fit_and_score(states: np.ndarray, labels: np.ndarray, steps: int, seed: int) -> dict:
    """Held-out scores of a network fitted to labels on the first 80 % of the states."""
    torch.manual_seed(seed)
    x = torch.tensor(scale_state(states), dtype=torch.float32)
    y = torch.tensor(labels)
    cut = int(0.8 * len(states))
    net = QNetwork(near_pad=True)
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    for _ in range(steps):
        i = torch.randint(0, cut, (512,))
        loss = torch.nn.functional.cross_entropy(net(x[i]), y[i])
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():
        pred = net(x).argmax(1).numpy()
    lp, lt = DEFAULT_ACTIONS.level_table[pred], DEFAULT_ACTIONS.level_table[labels]
    return {
        "train": float(np.mean(pred[:cut] == labels[:cut])),
        "test": float(np.mean(pred[cut:] == labels[cut:])),
        "axis": (lp[cut:] == lt[cut:]).mean(0),
        "levels": np.abs(lp[cut:] - lt[cut:]).mean(0),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--policy", default="models/pd_dqn_ocp.pt")
    p.add_argument("--teacher", default="mpc-fuel-reserve")
    p.add_argument("--episodes", type=int, default=50)
    p.add_argument("--seed", type=int, default=5000)
    p.add_argument("--dispersions", default="")
    p.add_argument("--steps", type=int, default=3000, help="fitting steps of 512 states")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--fit-seed", type=int, default=0, help="torch seed of each fit")
    a = p.parse_args()
    torch.set_num_threads(1)  # the same fits on any machine

    t0 = time.perf_counter()
    d = student_labels(a.policy, a.teacher, a.episodes, a.seed, a.dispersions, workers=a.workers)
    states, warm = d["states"], d["labels"]
    took = time.perf_counter() - t0
    print(f"{len(states)} states of {a.episodes} episodes, warm labels in {took:.0f} s")
    t0 = time.perf_counter()
    parts = np.array_split(states, 8 * a.workers)
    with get_context("spawn").Pool(a.workers) as pool:
        cold = np.concatenate(pool.map(cold_labels, [(a.teacher, s) for s in parts]))
    print(f"cold labels in {time.perf_counter() - t0:.0f} s")

    lw, lc = DEFAULT_ACTIONS.level_table[warm], DEFAULT_ACTIONS.level_table[cold]
    same_axis = np.round((lw == lc).mean(0), 3).tolist()
    print(f"warm = cold: {np.mean(warm == cold):.3f} of actions; per axis (x, y, z) {same_axis}")
    print("\n| labels | train acc | held-out acc | held-out per axis (x, y, z) | |level error| |")
    print("| --- | --- | --- | --- | --- |")
    for name, labels in (("warm (DAgger)", warm), ("cold (from the state)", cold)):
        r = fit_and_score(states, labels, a.steps, a.fit_seed)
        axis, levels = np.round(r["axis"], 3).tolist(), np.round(r["levels"], 2).tolist()
        print(f"| {name} | {r['train']:.3f} | {r['test']:.3f} | {axis} | {levels} |")


if __name__ == "__main__":
    main()
