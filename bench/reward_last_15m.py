"""Why an agent without demonstrations falls through the last 15 m (Sec. 4.4, Agent 2): Eq. 12's
returns there, measured with our reward and dynamics, no learning involved.

    python bench/reward_last_15m.py [--speeds 2 5 10 14]

From 15 m altitude above the pad, descending at each entry speed, two ways down are flown without
disturbance, and their discounted (gamma of Table 2) and undiscounted returns printed side by side:
- fall: no vertical thrust, so the lander hits the ground at 11-18 m/s and earns no landing bonus;
- track: each step the action that best follows Eq. 13's target velocity (one-step lookahead
  over the 147 actions), which touches down softly and earns kappa.
The column "track w/o kappa" is the same flight valued by an agent that has never landed (no
demonstrations, no lucky landing yet), so has never seen the bonus: where *fall* beats it, such an
agent is right, by its own estimates, to fall through the last 15 m, because the reward's switch at
15 m (Eqs. 16-18) makes the target speed drop while every step still costs alpha * |velocity error|
and eta per step does not pay for the slower descent.
"""

from __future__ import annotations

import argparse

import numpy as np

from pd_core.actions import DEFAULT_ACTIONS
from pd_core.config import DQN_PAPER, REWARD
from pd_core.lander import transition
from pd_core.reward import target_velocity

MAX_STEPS = 750  # 150 s


def fly(state: np.ndarray, policy: str) -> tuple[list[float], np.ndarray, bool]:
    """(rewards, final state, landed) flying from `state` with `policy` ('fall' or 'track')."""
    thrusts = DEFAULT_ACTIONS.thrust(np.arange(DEFAULT_ACTIONS.n))
    zero = np.zeros(3)
    rewards: list[float] = []
    for _ in range(MAX_STEPS):
        if policy == "fall":
            a = DEFAULT_ACTIONS.n // 2 // 3 * 3  # i, j centred, lowest vertical level
            thrust = thrusts[a]
        else:
            nxt, _r, _t, _ok = transition(np.repeat(state[None], len(thrusts), 0), thrusts, zero)
            err = np.linalg.norm(nxt[:, 3:6] - target_velocity(nxt[:, 0:3], nxt[:, 3:6]), axis=1)
            thrust = thrusts[int(np.argmin(err))]
        state, r, term, ok = transition(state, thrust, zero)
        rewards.append(float(r))
        if term:
            return rewards, state, bool(ok)
    return rewards, state, False


def discounted(rewards: list[float], gamma: float) -> float:
    return float(np.sum(np.asarray(rewards) * gamma ** np.arange(len(rewards))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--speeds", type=float, nargs="+", default=[2.0, 5.0, 10.0, 14.0])
    ap.add_argument("--mass", type=float, default=1700.0, help="mass at 15 m (kg)")
    a = ap.parse_args()
    g = DQN_PAPER.gamma
    print(f"From 15 m, no disturbance; gamma = {g}; kappa = {REWARD.kappa}")
    print(
        f"{'entry m/s':>9} | {'fall: disc':>10} {'undisc':>8} {'vk at 0':>8} {'steps':>5} | "
        f"{'track: disc':>11} {'undisc':>8} {'vk at 0':>8} {'steps':>5} {'landed':>6} | "
        f"{'track w/o kappa':>15} | better without kappa"
    )
    for v in a.speeds:
        s0 = np.array([0.0, 0.0, 15.0, 0.0, 0.0, -v, a.mass])
        rf, sf, _ = fly(s0, "fall")
        rt, st, ok = fly(s0, "track")
        df, dt = discounted(rf, g), discounted(rt, g)
        blind = dt - (REWARD.kappa * g ** (len(rt) - 1) if ok else 0.0)
        print(
            f"{v:9.1f} | {df:10.3f} {sum(rf):8.3f} {sf[5]:8.2f} {len(rf):5d} | "
            f"{dt:11.3f} {sum(rt):8.3f} {st[5]:8.2f} {len(rt):5d} {str(ok):>6} | "
            f"{blind:15.3f} | {'fall' if df > blind else 'track'}"
        )


if __name__ == "__main__":
    main()
