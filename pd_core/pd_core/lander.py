"""One lander through one episode, without Gymnasium: the step function every env shares.

`transition` is the one step of the dynamics and reward that the Gymnasium env (`pd_core.env`),
the vector env, the demonstrations and the simulator node all call; `Lander` is a single
lander's episode over it (seeded start, disturbance knots, status), which `pd_core.sim` flies
and `pd_core.env.PoweredDescentEnv` exposes to Gymnasium.

Episodes end (terminated) on the first step whose altitude is below 0.01 m (Sec. 4.2), landed or
not; they are truncated, not terminated, at `max_time_s` (MAX_EPISODE_TIME_S, ours), so the value
of a state at the time limit is still bootstrapped by learners.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Any

import numpy as np

from pd_core import dynamics
from pd_core.actions import DEFAULT_ACTIONS, ActionSpace
from pd_core.config import (
    DT_S,
    ISP_S,
    MAX_EPISODE_TIME_S,
    REWARD,
    STATE_SCALE,
    TABLE3,
    RewardConfig,
    StateRange,
)
from pd_core.disturbance import sample_knots
from pd_core.reward import landed as landed_condition
from pd_core.reward import reward as shaped_reward
from pd_core.reward import reward_scalar
from pd_core.state import check_state


class Status(IntEnum):
    """Episode status; the numbers match pd_interfaces/msg/LanderState."""

    FLYING = 0
    LANDED = 1
    CRASHED = 2
    OUT_OF_TIME = 3


def transition(
    state: np.ndarray,
    thrust_n: np.ndarray,
    force_n: np.ndarray,
    dt_s: float = DT_S,
    reward_cfg: RewardConfig = REWARD,
    thrust_max_n: np.ndarray | None = None,
    *,
    plant_thrust_n: np.ndarray | None = None,
    isp_s: float | np.ndarray = ISP_S,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One environment step for states (..., 7): (next_state, reward, terminated, landed).

    The single env, the vector env, the demonstrations and the simulator node all call this.
    Under dispersions the plant flies `plant_thrust_n` (the delivered thrust) with specific
    impulse `isp_s`; the reward's control effort is always that of the command `thrust_n`.
    """
    plant = thrust_n if plant_thrust_n is None else plant_thrust_n
    nxt = dynamics.step(state, plant, force_n, dt_s, isp_s=isp_s)
    pos, vel = nxt[..., 0:3], nxt[..., 3:6]
    ok = landed_condition(pos, vel, reward_cfg)
    r = shaped_reward(pos, vel, thrust_n, reward_cfg, thrust_max_n, ok)
    return nxt, r, pos[..., 2] < reward_cfg.touchdown_altitude_m, ok


def transition_scalar(
    state: tuple[float, ...],
    thrust_n: tuple[float, float, float],
    force_n: tuple[float, float, float],
    dt_s: float = DT_S,
    reward_cfg: RewardConfig = REWARD,
    thrust_max_n: tuple[float, float, float] | None = None,
) -> tuple[tuple[float, ...], float, bool, bool]:
    """`transition` for one lander on Python floats (tests hold the two equal to 1e-12)."""
    nxt = dynamics.step_scalar(state, thrust_n, force_n, dt_s)
    r, ok = reward_scalar(nxt, thrust_n, reward_cfg, thrust_max_n)
    return nxt, r, nxt[2] < reward_cfg.touchdown_altitude_m, ok


def sample_initial_state(rng: np.random.Generator, box: StateRange = TABLE3) -> np.ndarray:
    """Uniform initial state (7,) over a box of Table 1 or 3."""
    return rng.uniform(box.lo, box.hi)


def status_of(terminated: bool, landed: bool, truncated: bool) -> Status:
    if terminated:
        return Status.LANDED if landed else Status.CRASHED
    return Status.OUT_OF_TIME if truncated else Status.FLYING


_SCALE = tuple(float(v) for v in STATE_SCALE)


def _scaled(state: tuple[float, ...]) -> np.ndarray:
    return np.array([v * s for v, s in zip(state, _SCALE, strict=True)], dtype=np.float32)


class Lander:
    """3-DOF Mars lander with 147 discrete thrust actions and the reward of Eq. 12, one episode
    at a time, with Gymnasium's reset/step contract but no Gymnasium import.

    Observation: the scaled state of Eqs. 20-21. `info["state"]` holds the physical state.
    reset(seed=..., options={"initial_state": [x, y, z, vx, vy, vz, m]}) starts from a given
    state, otherwise uniformly over `initial_range` (Table 3). Randomness comes from one
    generator, re-made from `seed` when one is given (as `gymnasium.Env.reset` does:
    PCG64 over `SeedSequence(seed)`), so a seed flies the same episode here and in the env.
    """

    def __init__(
        self,
        disturbance: bool = True,
        max_time_s: float = MAX_EPISODE_TIME_S,
        initial_range: StateRange = TABLE3,
        actions: ActionSpace = DEFAULT_ACTIONS,
        reward_cfg: RewardConfig = REWARD,
        dt_s: float = DT_S,
    ) -> None:
        self.disturbance = disturbance
        self.max_steps = round(max_time_s / dt_s)
        self.initial_range = initial_range
        self.actions = actions
        self.reward_cfg = reward_cfg
        self.dt_s = dt_s
        self._rng: np.random.Generator | None = None
        self._state: tuple[float, ...] = (0.0,) * 7
        self._initial: tuple[float, ...] = (0.0,) * 7
        self._knots: list[list[float]] = [[0.0] * 3] * 2
        self._table = [tuple(t) for t in actions.table_n.tolist()]
        self._thrust_max = tuple(float(v) for v in actions.limits.hi)
        self._steps = 0

    @property
    def state(self) -> np.ndarray:
        """Physical state [x, y, z, vx, vy, vz, m] (m, m/s, kg)."""
        return np.array(self._state)

    @property
    def time_s(self) -> float:
        return self._steps * self.dt_s

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(seed)
        return self._start(self._rng, options)

    def _start(
        self, rng: np.random.Generator, options: dict[str, Any] | None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Begin an episode drawing from `rng` (the initial state, then the disturbance knots)."""
        options = options or {}
        if options.get("initial_state") is not None:
            state = check_state(options["initial_state"]).reshape(7)
        else:
            state = sample_initial_state(rng, self.initial_range)
        self._state = tuple(state.tolist())
        self._initial = self._state
        self._knots = sample_knots(rng, self.max_steps * self.dt_s).tolist()
        self._steps = 0
        return _scaled(self._state), {"state": state}

    def disturbance_force(self) -> tuple[float, float, float]:
        """F_env (N) applied over the next step: its mean, the value at the step's midpoint.

        dt divides the 1 s knot interval, so a step never straddles a knot and the midpoint
        value of the linear interpolation is its exact average over the step.
        """
        if not self.disturbance:
            return (0.0, 0.0, 0.0)
        t = (self._steps + 0.5) * self.dt_s
        i = min(int(t), len(self._knots) - 2)
        f = min(t - i, 1.0)
        a, b = self._knots[i], self._knots[i + 1]
        return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]))

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not isinstance(action, (int, np.integer)) or not 0 <= action < len(self._table):
            raise ValueError(
                f"action must be an integer in [0, {len(self._table)}), got {action!r}"
            )
        return self.step_thrust(self._table[action])

    def step_thrust(
        self, thrust_n: tuple[float, float, float] | np.ndarray
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Step with a thrust vector (N) instead of an action index (used for demonstrations)."""
        if isinstance(thrust_n, np.ndarray):
            thrust_n = tuple(thrust_n.tolist())
        nxt, r, terminated, ok = transition_scalar(
            self._state,
            thrust_n,
            self.disturbance_force(),
            self.dt_s,
            self.reward_cfg,
            self._thrust_max,
        )
        self._state = nxt
        self._steps += 1
        truncated = (not terminated) and self._steps >= self.max_steps
        info = {
            "state": np.array(nxt),
            "landed": ok and terminated,
            "status": int(status_of(terminated, ok, truncated)),
            "time_s": self._steps * self.dt_s,
            "fuel_kg": self._initial[6] - nxt[6],
        }
        return _scaled(nxt), r, terminated, truncated, info
