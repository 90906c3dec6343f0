"""The batched vector env: N landers stepped together by `pd_core.env.transition`."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils.seeding import np_random

from pd_core.actions import DEFAULT_ACTIONS, ActionSpace
from pd_core.config import (
    DT_S,
    MAX_EPISODE_TIME_S,
    REWARD,
    TABLE3,
    RewardConfig,
    StateRange,
)
from pd_core.dispersions import (
    NOMINAL,
    DispersionArrays,
    Dispersions,
    draw_episode,
    load_scenarios,
)
from pd_core.disturbance import force_at, sample_knots
from pd_core.env import OBSERVATION_SPACE
from pd_core.lander import sample_initial_state, transition
from pd_core.state import check_state, scale_state


class PoweredDescentVectorEnv:
    """N independent landers stepped together by `transition`.

    Sub-env i seeded with `seed + i` flies exactly what `PoweredDescentEnv` seeded with `seed + i`
    flies (nominal dispersions). With `autoreset` (training) an ended episode restarts in the same
    step: its final observation/state are in `info["final_obs"]` / `info["final_state"]` and the
    returned observation is already the next episode's first. Without it (evaluation) `reset`
    starts a fixed set of episodes, one per sub-env: an ended sub-env is frozen (no longer
    stepped, reward 0, `active` False) until the next `reset`, so `while env.active.any()` flies
    exactly those episodes.

    `dispersions` (one `Dispersions`, or several: each episode then picks one, uniformly or with
    `set_scenario_probs`) are off by default. Observations are of the state the agent observes
    (`observed_states`: the true state plus the episode's navigation noise); `states` and
    `info["state"]` are true states.
    """

    def __init__(
        self,
        num_envs: int,
        disturbance: bool = True,
        max_time_s: float = MAX_EPISODE_TIME_S,
        initial_range: StateRange = TABLE3,
        actions: ActionSpace = DEFAULT_ACTIONS,
        reward_cfg: RewardConfig = REWARD,
        dt_s: float = DT_S,
        autoreset: bool = True,
        *,
        dispersions: Dispersions | Sequence[Dispersions] = NOMINAL,
    ) -> None:
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        self.num_envs = num_envs
        self.disturbance = disturbance
        self.max_steps = round(max_time_s / dt_s)
        self.initial_range = initial_range
        self.actions = actions
        self.reward_cfg = reward_cfg
        self.dt_s = dt_s
        self.autoreset = autoreset
        self.single_action_space = spaces.Discrete(actions.n)
        self.single_observation_space = OBSERVATION_SPACE
        scen = (dispersions,) if isinstance(dispersions, Dispersions) else tuple(dispersions)
        if not scen:
            raise ValueError("dispersions: give at least one scenario")
        self.scenarios = scen
        self._boxes = [d.initial_box(initial_range) for d in scen]
        self._nominal = all(d.nominal for d in scen)
        self._rngs = [np_random(None)[0] for _ in range(num_envs)]
        self._duration = self.max_steps * dt_s
        k = sample_knots(self._rngs[0], self._duration).shape[0]
        self._knots = np.zeros((num_envs, k, 3))
        self.states = np.zeros((num_envs, 7))
        self.initial_states = np.zeros((num_envs, 7))
        self.steps = np.zeros(num_envs, dtype=np.int64)
        self._active = np.ones(num_envs, dtype=bool)
        self._thrust_max = actions.limits.hi
        self._disp = DispersionArrays(num_envs, scen, self.max_steps)
        self._probs: np.ndarray | None = None

    @property
    def active(self) -> np.ndarray:
        """(N,) bool: sub-envs whose episode is still flying (always True with autoreset)."""
        return self._active.copy()

    @property
    def observed_states(self) -> np.ndarray:
        """(N, 7) the physical states the agent observes (true states plus navigation noise)."""
        return self._disp.observed(self.states, self.steps)

    @property
    def scenario_probs(self) -> np.ndarray | None:
        """Probabilities each new episode draws the scenarios with (None: uniform)."""
        return None if self._probs is None else self._probs.copy()

    def set_scenario_probs(self, probs: np.ndarray | None) -> None:
        """Draw the scenarios of new episodes with `probs` (None: uniformly, the default)."""
        if probs is not None:
            probs = np.asarray(probs, dtype=float)
            if probs.shape != (len(self.scenarios),) or probs.min() < 0 or probs.sum() <= 0:
                raise ValueError(
                    f"scenario probabilities: need {len(self.scenarios)} non-negative numbers "
                    f"with a positive sum, got {probs!r}"
                )
            probs = probs / probs.sum()
        self._probs = probs

    @property
    def episode_scenarios(self) -> np.ndarray:
        """(N,) index into `scenarios` of each sub-env's current episode."""
        return self._disp.scenario.copy()

    def _draw_scenario(self, rng: np.random.Generator) -> int:
        if len(self.scenarios) == 1:
            return 0
        if self._probs is None:
            return int(rng.integers(len(self.scenarios)))
        return int(rng.choice(len(self.scenarios), p=self._probs))

    def _reset_one(self, i: int, initial_state: np.ndarray | None) -> None:
        rng = self._rngs[i]
        k = self._draw_scenario(rng)
        d = self.scenarios[k]
        if initial_state is None:
            self.states[i] = sample_initial_state(rng, self._boxes[k])
        else:
            self.states[i] = check_state(initial_state)
        knots = sample_knots(rng, self._duration)
        self._knots[i] = knots if d.disturbance_scale == 1.0 else knots * d.disturbance_scale
        self.steps[i] = 0
        self._active[i] = True
        if not self._nominal:
            dr = draw_episode(rng, d, self.max_steps)
            if dr.mass_kg is not None and initial_state is None:
                self.states[i, 6] = dr.mass_kg
            self._disp.set_episode(i, k, d, dr)
        self.initial_states[i] = self.states[i]

    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start every sub-env; `seed` s gives sub-env i the seed s + i (or a list of seeds);
        options={"initial_state": (N, 7)} starts from given states."""
        if seed is not None:
            seeds = [seed + i for i in range(self.num_envs)] if np.isscalar(seed) else list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"need {self.num_envs} seeds, got {len(seeds)}")
            self._rngs = [np_random(int(s))[0] for s in seeds]
        init = (options or {}).get("initial_state")
        for i in range(self.num_envs):
            self._reset_one(i, None if init is None else np.asarray(init, dtype=float)[i])
        observed = self.observed_states
        return scale_state(observed), {"state": self.states.copy(), "observed_state": observed}

    def _transition(
        self, idx: np.ndarray | slice, thrust: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """`transition` for the sub-envs `idx` under their dispersions."""
        states, steps = self.states[idx], self.steps[idx]
        if self.disturbance:
            force = force_at(self._knots[idx], (steps + 0.5) * self.dt_s)
        else:
            force = np.zeros_like(thrust)
        if self._nominal:
            return transition(states, thrust, force, self.dt_s, self.reward_cfg, self._thrust_max)
        wind = self._disp.wind(idx)
        if wind is not None:
            force = force + wind
        plant, isp = self._disp.plant(idx, thrust, steps)
        return transition(
            states,
            thrust,
            force,
            self.dt_s,
            self.reward_cfg,
            self._thrust_max,
            plant_thrust_n=plant,
            isp_s=isp,
        )

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        actions = np.asarray(actions)
        if actions.shape != (self.num_envs,):
            raise ValueError(f"need actions of shape ({self.num_envs},), got {actions.shape}")
        thrust = self.actions.thrust(actions)
        n = self.num_envs
        idx: np.ndarray | slice = (
            slice(None) if self._active.all() else np.flatnonzero(self._active)
        )
        nxt, r_live, term_live, ok_live = self._transition(idx, thrust[idx])
        self.states[idx] = nxt
        self.steps[idx] += 1
        r, term, ok = np.zeros(n), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        r[idx], term[idx], ok[idx] = r_live, term_live, ok_live
        trunc = ~term & (self.steps >= self.max_steps) & self._active
        done = term | trunc
        info: dict[str, Any] = {
            "state": self.states.copy(),
            "landed": ok & term,
            "fuel_kg": self.initial_states[:, 6] - self.states[:, 6],
            "steps": self.steps.copy(),
            "initial_state": self.initial_states.copy(),
            "scenario": self._disp.scenario.copy(),
        }
        if not self.autoreset:
            self._active &= ~done
            info["active"] = self._active.copy()
        observed = self.observed_states
        obs = scale_state(observed)
        if self.autoreset and np.any(done):
            info["final_obs"] = obs.copy()
            info["final_state"] = info["state"].copy()
            info["final_observed_state"] = observed.copy()
            for i in np.flatnonzero(done):
                self._reset_one(int(i), None)
            observed = self.observed_states
            obs[done] = scale_state(observed[done])
        info["observed_state"] = observed
        return obs, r, term, trunc, info

    # ---- checkpoints
    def state_dict(self) -> dict[str, Any]:
        """Everything needed to continue exactly: numpy arrays, plus `rngs` (the per-env
        Generator states, JSON-serialisable dicts) and `scenarios` (their field dicts)."""
        d: dict[str, Any] = {
            "states": self.states.copy(),
            "initial_states": self.initial_states.copy(),
            "steps": self.steps.copy(),
            "active": self._active.copy(),
            "knots": self._knots.copy(),
            "rngs": [r.bit_generator.state for r in self._rngs],
            "scenarios": [s.to_dict() for s in self.scenarios],
        }
        if self._probs is not None:
            d["scenario_probs"] = self._probs.copy()
        d.update(self._disp.state_dict())
        return d

    def load_state_dict(self, d: dict[str, Any]) -> None:
        """Restore `state_dict()` of an env made with the same arguments (ValueError if not)."""
        mine = [s.to_dict() for s in self.scenarios]
        if list(d.get("scenarios", mine)) != mine:
            raise ValueError(f"env state has dispersions {d['scenarios']}, this env {mine}")
        if len(d["rngs"]) != self.num_envs or np.shape(d["states"]) != self.states.shape:
            raise ValueError(
                f"env state is for {len(d['rngs'])} envs, this env has {self.num_envs}"
            )
        self.states = np.array(d["states"], dtype=float)
        self.initial_states = np.array(d["initial_states"], dtype=float)
        self.steps = np.array(d["steps"], dtype=np.int64)
        self._active = np.array(d.get("active", np.ones(self.num_envs)), dtype=bool)
        self._knots = np.array(d["knots"], dtype=float)
        for r, s in zip(self._rngs, d["rngs"], strict=True):
            r.bit_generator.state = s
        self._disp.load_state_dict(d)
        self.set_scenario_probs(d.get("scenario_probs"))


def make_vector_env(
    num_envs: int,
    disturbance: bool = True,
    max_time_s: float = MAX_EPISODE_TIME_S,
    reward_cfg: RewardConfig = REWARD,
    autoreset: bool = True,
    *,
    dispersions: str | Dispersions | Sequence[Dispersions] = "",
    initial_range: StateRange = TABLE3,
) -> PoweredDescentVectorEnv:
    """The env factory shared by training and evaluation (Table 3, disturbances on).

    `dispersions`: "" (nominal), a scenario name, a comma-separated list, a campaign name or a
    YAML file (`pd_core.dispersions.load_scenarios`), or Dispersions objects. With several
    scenarios each episode picks one (domain randomisation).
    """
    if isinstance(dispersions, str):
        dispersions = load_scenarios(dispersions) if dispersions.strip() else NOMINAL
    return PoweredDescentVectorEnv(
        num_envs,
        disturbance=disturbance,
        max_time_s=max_time_s,
        initial_range=initial_range,
        reward_cfg=reward_cfg,
        autoreset=autoreset,
        dispersions=dispersions,
    )
