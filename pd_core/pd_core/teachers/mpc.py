"""Receding-horizon optimal-control teacher (closed loop): re-plan the OCP at every step.

Issue 10's closed-loop teacher (ours; the paper's demonstrations are open loop, Sec. 2.2). Each
control period it solves Eq. 4 (objective "energy") or the fuel problem from the current state,
flies the plan's first step quantised to one of the 147 actions, and re-plans at the next state.

* **Warm start, known time-to-go.** The first state of an episode gets a cold free-final-time
  solve (`pd_core.ocp.solve_problem`). After that, the time-to-go shrinks by dt each step and the
  re-plan is a fixed-t_f solve warm-started from the previous plan shifted by one step: one SQP
  pass of the tridiagonal QP (energy, `ocp.qp.energy_at`) or one LP pass (fuel,
  `ocp.fuel.fuel_lp_at`, HiGHS), a few milliseconds instead of a t_f search.
* **Plan size and margin.** Control points every `control_spacing_s` of the time-to-go
  (between `min_control_points` and `max_control_points`): the plan shrinks with the horizon.
  Plans use `plan_thrust_fraction` (90 %) of the RL limits, leaving authority for the
  quantisation and the disturbance (a fuel-optimal plan brakes at its limit to the end).
* **Low gate.** Plans end at rest `gate_altitude_m` (2 m) above the pad, not on it: rest exactly
  on the pad at t_f -> 0 asks for infinite precision and leaves no room to correct.
* **Action (Eq. 5).** a* is the plan's first-step thrust normalised over the RL limits, and the
  level above or below it is chosen by the sign of the velocity error of Eq. 6, dv = v*_{t+1} -
  v_t (`pd_core.discretise.eq5_levels`, the rounding of the demonstrations). v*_{t+1} is the
  plan's next velocity: "eq5-replan" takes it from the plan just made (so dv is that plan's own
  first-step change); "eq5" carries the reference from plan to plan (the velocity the plans'
  continuous thrust would have flown, so dv holds the past quantisation error, as Eq. 6
  against an open-loop reference does). `mpc_controller` picks per objective (measured there).
* **Time-to-go.** Every `tf_trial_every` re-plans, a second solve at t_go +- `tf_step_s` lets
  t_f follow its optimum as the state drifts (a pattern search; the cheaper plan is kept).
* **No plans through the ground.** Eq. 4 has no altitude constraint (Sec. 2.1) and a fuel
  optimum may dive below the target and let gravity stop the climb back; fuel plans carry a
  linearised altitude floor, and any plan more than `underground_m` below the gate is refused.
* **Fallback (documented safe law).** The fallback controller (the ZEM/ZEV law, whose final
  descent at 0.8 m/s + 0.3 z lands every Table 3 case) flies the rest of the episode once the
  lander is within `terminal_altitude_m` of the gate or `terminal_time_s` of the plan's end, and
  whenever the OCP has no solution: a failed cold solve, or a warm re-plan infeasible at the
  time-to-go with the margin, then with the full limits, then with more time (`recovery`). So
  the teacher never fails for want of a plan, and never pays a cold solve mid-flight.

* **Keeping the layer's reserve** (`mpc-fuel-reserve`, `reserve_controller`, issue 32): the
  fuel plans round to the nearest level and `keep_brake_limit` raises the vertical level where
  the runtime layer's braking limit would (`brake_limited`), so the layer rarely changes an
  action. The fuel-optimal plan at 90 % of the thrust counts on the mass it will have lost when
  it brakes and rides outside that limit; a plan inside it costs >= 1.04x the fuel optimum
  (`bench/envelope_floor.py`).

Plans are matched to states, not to row numbers: `pd_core.episodes.rollout` passes
only the
landers still flying, so rows shift as episodes end. Each plan remembers the state it predicts
next (the commanded action, no disturbance); an incoming state continues the plan whose
prediction is nearest within `continuity_*` (normalised, greedy), and a state that continues no
plan starts a new episode (a cold solve). Without navigation noise a true continuation is
within millimetres of its prediction and other episodes are metres or kilograms away, so the
matching, and hence every action, depends only on the episode's own history. `begin_episode`
(called by `Runtime.begin_episode(s)`) forgets every plan, so a state that starts an episode is
never taken for the continuation of the last one; `propose` is `act_batch` that changes no plan
(`Runtime.bare_action`).
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from pd_core import envelope, ocp
from pd_core.actions import DEFAULT_ACTIONS, ActionSpace
from pd_core.config import (
    BRAKE_MARGIN,
    DT_S,
    GRAVITY_MPS2,
    LAND_SPEED_MPS,
    TOUCHDOWN_SPEED_MPS,
    ThrustLimits,
)
from pd_core.discretise import eq5_levels
from pd_core.dynamics import step_scalar
from pd_core.ocp.fuel import BrakeEnvelope, envelope_fuel_plan, fuel_lp_plan
from pd_core.ocp.lp import LPSolver
from pd_core.ocp.model import control_times
from pd_core.ocp.qp import WarmStart, energy_qp_plan
from pd_core.state import check_state
from pd_core.teachers.mpc_params import MPCParams

_ZERO = (0.0, 0.0, 0.0)


class Actor(Protocol):
    def act_batch(self, states: np.ndarray) -> np.ndarray: ...


@dataclass
class _Row:
    """One episode's plan: control points over the time-to-go from the last state."""

    p: np.ndarray | None = None  # (n, 3) N; None: no plan (fallback)
    t_go: float = 0.0  # s, from the state the plan was made for
    active: np.ndarray | None = None  # warm active set of the energy QP
    predicted: np.ndarray | None = None  # (7,) state expected next (commanded action, no wind)
    terminal: bool = False  # near the pad or no plan: the fallback flies the rest
    v_ref: np.ndarray | None = None  # (3,) m/s, the reference velocity of Eq. 6 (see eq5)
    replans: int = 0
    tf_dir: float = -1.0  # direction of the next t_f trial (+1 longer, -1 shorter)


@dataclass
class ReplanStats:
    """Time of every re-plan (s), by kind, wall clock and this thread's CPU time (the figure
    that holds on a machine other processes load), for bench/mpc_speed.py."""

    warm: list[float] = field(default_factory=list)
    cold: list[float] = field(default_factory=list)
    warm_cpu: list[float] = field(default_factory=list)
    cold_cpu: list[float] = field(default_factory=list)
    fallback_steps: int = 0
    full_limits: int = 0  # warm re-plans that needed the full RL limits (`recovery`)


class MPCController:
    """Closed-loop teacher with the interface of `ZemZevController` (act, act_batch, thrust,
    propose, begin_episode); its memory is the plans of the episodes in flight (see the module
    docstring), forgotten by `begin_episode`, never touched by `propose`."""

    def __init__(
        self,
        params: MPCParams | None = None,
        fallback: Actor | None = None,
        actions: ActionSpace = DEFAULT_ACTIONS,
    ) -> None:
        self.params = params or MPCParams()
        if fallback is None:
            raise ValueError("MPCController needs a fallback controller (e.g. ZemZevController)")
        self.fallback = fallback
        self.actions = actions
        self.name = f"mpc-{self.params.objective}"
        self._lo, self._hi = actions.limits.lo, actions.limits.hi
        self._n = np.asarray(actions.n_per_axis)
        # the problem built once; `at` re-uses it from each state (checks included)
        origin = np.array([0.0, 0.0, 1000.0, 0.0, 0.0, -50.0, 2000.0])
        f = self.params.plan_thrust_fraction
        fz = self.params.vertical_thrust_fraction
        scale = np.array([f, f, f if fz is None else fz])
        limits = ThrustLimits(
            tuple(scale * actions.limits.lo),  # type: ignore[arg-type]
            tuple(scale * actions.limits.hi),  # type: ignore[arg-type]
        )
        self._problem = ocp.Problem(
            origin[0:3], origin[3:6], origin[6], self.params.objective, 2, limits
        )
        self._problem_full = replace(self._problem, limits=actions.limits)
        self._rows: list[_Row] = []
        # one HiGHS model for every fuel LP of this controller, passed as arrays (`LPSolver`;
        # with `warm_lp` each LP also starts from the last one's basis)
        self._highs = LPSolver(warm=self.params.warm_lp)
        self.stats = ReplanStats()
        # the vertical thrust fraction the layer counts on, per state of the next act_batch
        # (`take_thrust_fraction`; None: full thrust)
        self._fraction: np.ndarray | None = None
        self._row_fraction = 1.0  # the fraction of the state being planned from

    @property
    def takes_thrust_fraction(self) -> bool:
        """Whether a `Runtime` should hand this controller the fraction of the vertical
        thrust its layer counts on (`MPCParams.layer_thrust_fraction`)."""
        return self.params.layer_thrust_fraction

    def take_thrust_fraction(self, fraction: np.ndarray) -> None:
        """The fraction (B,) of the vertical thrust the runtime layer counts on for each state
        of the next `act_batch` call (used once, by `keep_brake_limit`)."""
        self._fraction = np.asarray(fraction, dtype=float).reshape(-1)

    def begin_episode(self) -> None:
        """Every lander flown starts a new episode: forget every plan (each next state starts
        cold) and any thrust fraction handed over and not used. `Runtime.begin_episode(s)`
        calls it; `stats` keeps counting."""
        self._rows = []
        self._fraction = None

    def propose(self, states: np.ndarray) -> np.ndarray:
        """The actions (B,) `act_batch` would return for physical states (B, 7) on the plans
        held now, at full thrust, changing nothing: the plans, the thrust fraction handed over,
        `stats` and the LP's warm basis are put back as they were (`Runtime.bare_action`). It
        flies `act_batch` on a copy of the plans (a continued plan is changed in place) with a
        shallow copy of the LP solver (the same HiGHS object, which each LP re-loads whole)."""
        held = self._rows, self._fraction, self._row_fraction, self.stats, self._highs
        self._rows, self._fraction = copy.deepcopy(self._rows), None
        self.stats, self._highs = ReplanStats(), copy.copy(self._highs)
        try:
            return self.act_batch(states)
        finally:
            self._rows, self._fraction, self._row_fraction, self.stats, self._highs = held

    def thrust(self, action: int) -> np.ndarray:
        return self.actions.thrust(int(action))

    def act(self, state: np.ndarray) -> int:
        return int(self.act_batch(np.asarray(state, dtype=float).reshape(1, 7))[0])

    def act_batch(self, states: np.ndarray) -> np.ndarray:
        """Actions (B,) for physical states (B, 7), each continuing the plan it matches."""
        s = check_state(states).reshape(-1, 7)
        frac, self._fraction = self._fraction, None
        if frac is None or len(frac) != len(s):
            frac = np.ones(len(s))
        rows = self._match(s)
        out = np.empty(len(s), dtype=np.int64)
        for i, row in enumerate(rows):
            out[i] = self._act_row(row, s[i], float(frac[i]))
        self._rows = rows  # plans no state continued belong to finished episodes
        return out

    def _match(self, s: np.ndarray) -> list[_Row]:
        """The plan each state continues (greedy, nearest normalised prediction first) or a
        new one."""
        rows = [_Row() for _ in range(len(s))]
        old = [r for r in self._rows if r.predicted is not None]
        if not old:
            return rows
        p = self.params
        pred = np.stack([r.predicted for r in old])  # type: ignore[misc]
        d = np.abs(s[:, None, :] - pred[None, :, :])
        dist = np.maximum(
            np.maximum(
                d[..., 0:3].max(-1) / p.continuity_m, d[..., 3:6].max(-1) / p.continuity_mps
            ),
            d[..., 6] / p.continuity_kg,
        )
        taken = np.zeros(len(old), dtype=bool)
        for flat in np.argsort(dist, axis=None):
            i, j = divmod(int(flat), len(old))
            if dist[i, j] >= 1.0:
                break
            if rows[i].predicted is None and not taken[j]:
                rows[i], taken[j] = old[j], True
        return rows

    def first_action(self, state: np.ndarray) -> int:
        """Eq. 5 action of a cold free-final-time plan from `state` (fallback if none), without
        touching the plans of `act_batch`."""
        return self._act_row(_Row(), check_state(state).reshape(7), 1.0)

    # --- one row ---------------------------------------------------------------------------

    def _act_row(self, row: _Row, s: np.ndarray, fraction: float = 1.0) -> int:
        self._row_fraction = fraction if self.params.layer_thrust_fraction else 1.0
        planned = self._plan(row, s)
        if planned is None:
            self.stats.fallback_steps += 1
            row.p, row.v_ref = None, None
            action = int(self.fallback.act_batch(s.reshape(1, 7))[0])
        else:
            action = self._eq5_action(row, s, planned)
        if self.params.keep_brake_limit:
            action = self._within_brake_limit(s, action, fraction)
        row.predicted = np.array(step_scalar(tuple(s), tuple(self.thrust(action)), _ZERO, DT_S))
        return action

    def _within_brake_limit(self, s: np.ndarray, action: int, fraction: float = 1.0) -> int:
        """The action with its vertical level raised to the lowest one the runtime layer's
        braking limit lets pass from s (the top level if none does), counting on `fraction`
        of the vertical thrust where `layer_thrust_fraction` (as the layer's rules do: the
        command and the full thrust both scaled) and on the mass lost while braking where
        `brake_mass_loss`."""
        levels = self.actions.level_table[action].copy()
        top = self.actions.n_per_axis[2] - 1
        f = fraction if self.params.layer_thrust_fraction else 1.0
        mass_loss = self.params.brake_mass_loss
        while levels[2] < top:
            t_z = float(self.actions.levels_to_thrust(levels)[2])
            if not brake_limited(s, f * t_z, f * float(self._hi[2]), mass_loss=mass_loss):
                break
            levels[2] += 1
        return int(self.actions.levels_to_action(levels[None])[0])

    def _envelope(self) -> BrakeEnvelope | None:
        """The braking limit the fuel plans keep inside (`plan_brake_margin_mps`), or None."""
        p = self.params
        if p.plan_brake_margin_mps is None:
            return None
        return BrakeEnvelope(
            thrust_margin=BRAKE_MARGIN * self._row_fraction,
            max_vertical_thrust_n=float(self._hi[2]),
            land_speed_mps=LAND_SPEED_MPS,
            margin_mps=p.plan_brake_margin_mps,
            gate_m=p.gate_altitude_m,
            mass_loss=p.brake_mass_loss,
        )

    def _to_gate(self, s: np.ndarray) -> np.ndarray:
        """The state relative to the gate the plans aim at (rest, gate_altitude_m up)."""
        g = s.copy()
        g[2] -= self.params.gate_altitude_m
        return g

    def _n_control(self, t_go: float) -> int:
        p = self.params
        n = math.ceil(t_go / p.control_spacing_s) + 1
        return int(min(max(n, p.min_control_points), p.max_control_points))

    def _plan(self, row: _Row, s: np.ndarray) -> tuple[np.ndarray, float] | None:
        """(control points (n, 3) N, t_go s) from s, or None: the fallback flies this step."""
        p = self.params
        if p.handover_from_state:
            near_end = time_to_rest_s(s, p.gate_altitude_m) < p.terminal_time_s
        else:
            near_end = row.p is not None and row.t_go - DT_S < p.terminal_time_s
        row.terminal |= bool(s[2] - p.gate_altitude_m < p.terminal_altitude_m) or near_end
        if row.terminal:
            return None
        t0, c0 = time.perf_counter(), time.thread_time()
        if row.p is None:  # a new episode
            plan = self._cold(row, s)
            self.stats.cold.append(time.perf_counter() - t0)
            self.stats.cold_cpu.append(time.thread_time() - c0)
        else:
            # the known time-to-go first; if the state has drifted too far for it (a plan at
            # its thrust limit), a little more time
            plan = None
            for full, extra_s in p.recovery:
                plan = self._warm(row, s, row.t_go - DT_S + extra_s, full)
                if plan is not None:
                    self.stats.full_limits += full
                    break
            self.stats.warm.append(time.perf_counter() - t0)
            self.stats.warm_cpu.append(time.thread_time() - c0)
        row.terminal = plan is None  # no plan: the fallback lands the rest of the episode
        return plan

    def _warm(
        self, row: _Row, s: np.ndarray, t_go: float, full: bool = False
    ) -> tuple[np.ndarray, float] | None:
        """Fixed-t_f re-plan at t_go, and every `tf_trial_every` re-plans also at t_go +
        `tf_step_s` in the direction that last paid (a pattern search that lets t_f follow its
        optimum as the state drifts); the cheaper feasible one is kept."""
        best = self._warm_at(row, s, t_go, full)
        row.replans += 1
        trial = row.replans % self.params.tf_trial_every == 0
        step = self.params.tf_step_s * row.tf_dir if trial else 0.0
        other = self._warm_at(row, s, t_go + step, full) if step else None
        if other is not None and (best is None or other[2] < best[2]):
            best = other
        elif step:
            row.tf_dir = -row.tf_dir  # the other direction next time
        if best is None:
            return None
        row.p, row.t_go, _, row.active = best
        return best[0], best[1]

    def _warm_at(
        self, row: _Row, s: np.ndarray, t_go: float, full: bool
    ) -> tuple[np.ndarray, float, float, np.ndarray | None] | None:
        """(control points, t_go, cost, QP active set) of a re-plan at t_go from the previous
        plan shifted by one step (within the full RL limits if `full`, else the plan margin),
        or None if infeasible."""
        assert row.p is not None
        if t_go < self.params.terminal_time_s:
            return None
        n = self._n_control(t_go)
        pb = (self._problem_full if full else self._problem).at(self._to_gate(s), n_control=n)
        old_t = control_times(row.t_go, len(row.p))
        new_t = control_times(t_go, n) + DT_S
        warm = np.column_stack([np.interp(new_t, old_t, row.p[:, a]) for a in range(3)])
        st = WarmStart(warm, row.active if n == len(row.p) else None)
        g = pb.grid(t_go)
        if self.params.objective == "energy":
            out = energy_qp_plan(pb, g, st, self.params.passes)
            plan = None if out is None else out[0]
        else:
            plan = fuel_lp_plan(
                pb,
                g,
                warm,
                self.params.passes,
                self._highs,
                self.params.floor_every,
                envelope=self._envelope(),
                lateral_settle_s=self.params.lateral_settle_s,
            )
        if plan is None:
            return None
        fl = pb.fly(plan, g)
        if pb.altitudes(fl, g).min() < -self.params.underground_m:
            return None  # through the ground to the gate: no plan to fly
        return plan, t_go, pb.cost(fl, g), st.active

    def _cold(self, row: _Row, s: np.ndarray) -> tuple[np.ndarray, float] | None:
        """Free-final-time plan from s (the episode's first state, or after a failure)."""
        n0 = self.params.max_control_points
        try:
            pb = self._problem.at(self._to_gate(s), n_control=n0)
        except ValueError:
            return None
        res = ocp.solve_problem(pb)
        if not res.success or res.time_of_flight < self.params.terminal_time_s:
            return None  # no plan, or close enough to the pad for the fallback
        p, t_f = res.thrust, res.time_of_flight
        env = self._envelope()
        if env is not None:
            # a plan inside the limit needs more time than the unreserved optimum: t_f searched
            # with the envelope (`envelope_fuel_plan`); none found: the unreserved plan
            inside = envelope_fuel_plan(pb, p, t_f, env, self._highs, self.params.floor_every)
            if inside is not None:
                p, t_f = inside
        g = pb.grid(t_f)
        settle = self.params.lateral_settle_s
        if self.params.objective == "fuel" and (self.params.floor_every or settle):
            # the free-t_f fuel optimum may dive below the gate, and brakes its horizontal
            # motion last: LP passes with the floor and the settle
            p = fuel_lp_plan(
                pb, g, p, 3, self._highs, self.params.floor_every, self._envelope(), settle
            )
            if p is None:
                return None
        if pb.altitudes(pb.fly(p, g), g).min() < -self.params.underground_m:
            return None
        n = self._n_control(t_f)
        if n != n0:  # resample the plan to the size warm re-plans will use
            old_t = control_times(t_f, n0)
            new_t = control_times(t_f, n)
            p = np.column_stack([np.interp(new_t, old_t, p[:, a]) for a in range(3)])
        row.p, row.t_go, row.active = p, t_f, None
        return p, t_f

    def _eq5_action(self, row: _Row, s: np.ndarray, plan: tuple[np.ndarray, float]) -> int:
        """Eq. 5: a* of the plan's first step, rounded by the sign of dv = v*_{t+1} - v_t.

        v* is the reference velocity the plans' continuous thrust would have flown ("eq5"):
        it advances by each plan's first-step velocity change and is not reset to the measured
        velocity, so dv carries the quantisation error of the past steps (clipped to
        `reference_clip_mps`), as Eq. 6 does against an open-loop reference. "eq5-replan"
        resets it every step (dv is then the plan's own first-step change, which rounds every
        deceleration up); "nearest" rounds a* to the nearest level (not the paper's).
        """
        p, t_go = plan
        # thrust of the first step: the plan interpolated at the step's midpoint (as `Grid`)
        t_ctrl = control_times(t_go, len(p))
        u0 = np.array([np.interp(0.5 * DT_S, t_ctrl, p[:, a]) for a in range(3)])
        dv_plan = np.array(step_scalar(tuple(s), tuple(u0), _ZERO, DT_S)[3:6]) - s[3:6]
        a_star = np.clip((u0 - self._lo) / (self._hi - self._lo), 0.0, 1.0)
        mode = self.params.rounding
        if mode == "nearest":
            levels = np.rint(a_star * (self._n - 1)).astype(np.int64)
            return int(self.actions.levels_to_action(levels[None])[0])
        v_ref = s[3:6] if row.v_ref is None or mode == "eq5-replan" else row.v_ref
        c = self.params.reference_clip_mps
        v_next = s[3:6] + np.clip(v_ref - s[3:6], -c, c) + dv_plan  # v*_{t+1}
        row.v_ref = v_next
        levels = eq5_levels(a_star, v_next - s[3:6], self._n)
        return int(self.actions.levels_to_action(levels[None])[0])


def brake_limited(
    s: np.ndarray,
    vertical_thrust_n: float,
    max_vertical_thrust_n: float,
    margin: float = BRAKE_MARGIN,
    land_speed_mps: float = LAND_SPEED_MPS,
    touchdown_speed_mps: float = TOUCHDOWN_SPEED_MPS,
    mass_loss: bool = False,
) -> bool:
    """True where the runtime layer's braking limit would fire on a vertical command (N) from
    state s (7,): `pd_core.envelope.brake_fires` (one step of the command counted at `margin`,
    against the limit of margin x max_vertical_thrust_n, at the mass now or, with mass_loss,
    counting on the mass lost while braking), the law the layer compiles
    (tests/unit/teachers/test_mpc_reserve.py checks they agree)."""
    fired = envelope.brake_fires(
        float(s[2]), float(s[5]), float(s[6]), margin * vertical_thrust_n,
        margin * max_vertical_thrust_n, land_speed_mps, touchdown_speed_mps,
        -float(GRAVITY_MPS2[2]), DT_S, mass_loss,
    )  # fmt: skip
    return fired != envelope.NO_LIMIT


def time_to_rest_s(s: np.ndarray, gate_altitude_m: float) -> float:
    """Seconds to come to rest at the gate from state s braking evenly: 2 h / |vz| for a
    descent of h m above the gate (inf while climbing or hovering)."""
    h = max(float(s[2]) - gate_altitude_m, 0.0)
    return 2.0 * h / -float(s[5]) if s[5] < 0.0 else math.inf
