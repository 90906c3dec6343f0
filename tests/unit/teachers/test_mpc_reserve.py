"""Issue 32, stage 1: the reserve-keeping fuel teacher (`mpc-fuel-reserve`), its braking-limit
check, the LP solver its re-plans share, the LAPACK tridiagonal solve and the braking envelope
of `bench/envelope_floor.py`."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import solve_banded

from pd_core import ocp
from pd_core.actions import DEFAULT_ACTIONS
from pd_core.config import BRAKE_MARGIN, LAND_SPEED_MPS, RL_THRUST, ThrustLimits
from pd_core.episodes import rollout
from pd_core.ocp.fuel import (
    BrakeEnvelope,
    envelope_excess,
    envelope_fuel_plan,
    fuel_lp_plan,
    fuel_weights,
)
from pd_core.ocp.lp import LPSolver, solve_lp
from pd_core.ocp.model import KN
from pd_core.ocp.qp import _kkt_solve
from pd_core.teachers.mpc import MPCController, brake_limited, time_to_rest_s
from pd_core.teachers.registry import CONTROLLERS, RESERVE_PARAMS, make_controller

T_MAX_N = float(RL_THRUST.max_n[2])


def _nominal_starts(n: int, seed: int = 0) -> np.ndarray:
    return rollout(make_controller("zemzev"), n, seed).initial_states


def _reserve_problem(seed: int) -> tuple[ocp.Problem, ocp.OCPResult]:
    """The fuel problem on 90 % of the RL limits from nominal start `seed`, and its optimum."""
    s = _nominal_starts(1, seed)[0]
    lim = ThrustLimits(
        tuple(0.9 * np.array(RL_THRUST.min_n)), tuple(0.9 * np.array(RL_THRUST.max_n))
    )
    pb = ocp.Problem(s[0:3], s[3:6], s[6], "fuel", 40, lim)
    return pb, ocp.solve_problem(pb)


def test_brake_limited_is_the_runtime_layers_rule() -> None:
    from pd_core.runtime.config import RulesConfig
    from pd_core.runtime.rules import brake_mask

    rng = np.random.default_rng(3)
    n = 4000
    s = np.zeros((n, 7))
    s[:, 2] = rng.uniform(-0.5, 400.0, n) * rng.uniform(0, 1, n) ** 2
    s[:, 5] = -rng.uniform(0.0, 60.0, n) * rng.uniform(0, 1, n)
    s[:, 6] = rng.uniform(1300.0, 2100.0, n)
    t_z = rng.choice([0.0, 0.5 * T_MAX_N, T_MAX_N], n)
    ours = np.array([brake_limited(s[i], t_z[i], T_MAX_N) for i in range(n)])
    theirs = brake_mask(s, t_z, T_MAX_N, RulesConfig())
    assert 0.05 < ours.mean() < 0.95  # both outcomes are exercised
    np.testing.assert_array_equal(ours, theirs)


def test_reserve_teacher_is_registered_and_keeps_its_vertical_fraction() -> None:
    assert "mpc-fuel-reserve" in CONTROLLERS
    ctl = make_controller("mpc-fuel-reserve")
    assert isinstance(ctl, MPCController) and ctl.name == "mpc-fuel-reserve"
    cap = RESERVE_PARAMS.plan_thrust_fraction * T_MAX_N
    seen: list[float] = []

    class Spy:
        def act_batch(self, states: np.ndarray) -> np.ndarray:
            full = ctl.stats.full_limits
            out = ctl.act_batch(states)
            if ctl.stats.full_limits == full:  # a plan within the margin (not a recovery)
                seen.extend(float(r.p[:, 2].max()) for r in ctl._rows if r.p is not None)
            return out

    ro = rollout(Spy(), 2, seed=0)
    assert ro.landed.all()
    assert len(seen) > 0.8 * ro.steps.sum()  # it flew on its plans
    assert max(seen) <= cap + 1e-6, max(seen)
    # a re-plan falls back on the full limits only where the margin has no plan (rare)
    assert ctl.stats.full_limits <= 0.05 * len(ctl.stats.warm)


@pytest.mark.timeout(600)
def test_reserve_teacher_lands_nominal_episodes_behind_the_layer_it_agrees_with() -> None:
    from pd_core.runtime.config import RuntimeConfig
    from pd_core.runtime.layer import Runtime

    rt = Runtime(make_controller("mpc-fuel-reserve"), RuntimeConfig())
    ro = rollout(rt, 4, seed=0)
    assert ro.landed.all(), np.flatnonzero(~ro.landed)
    steps = sum(rt.counts.values())
    assert rt.counts["brake"] == 0
    assert rt.changed <= 0.05 * steps, rt.counts


def _replan_lp(seed: int = 0) -> tuple[np.ndarray, ...]:
    """A warm re-plan's fuel LP (40 points) from a nominal state, and the next step's."""
    s = _nominal_starts(1, seed)[0]
    lim = ThrustLimits(
        tuple(0.9 * np.array(RL_THRUST.min_n)), tuple(0.9 * np.array(RL_THRUST.max_n))
    )
    pb = ocp.Problem(s[0:3], s[3:6], s[6], "fuel", 40, lim)
    res = ocp.solve_problem(pb)
    out = []
    for t_f in (res.time_of_flight, res.time_of_flight + 0.1):
        g = pb.grid(t_f)
        jac, rhs, _ = pb.linearised(res.thrust, g)
        a = np.concatenate([jac, -jac], axis=2).reshape(6, 240)
        hi = np.stack([np.maximum(lim.hi, 0.0), np.maximum(-lim.lo, 0.0)], 1) / KN
        out.append((np.tile(fuel_weights(g), 6), a, rhs, np.zeros(240), np.repeat(hi, 40)))
    return tuple(out)


def test_lp_solver_warm_basis_gives_the_same_optimum_as_a_cold_solve() -> None:
    (c0, a0, b0, lb, ub), (c1, a1, b1, _, _) = _replan_lp()
    warm = LPSolver(warm=True)
    assert warm.solve(c0, a0, b0, b0, lb, ub) is not None
    cold_its = None
    x_cold = solve_lp(c1, a1, b1, lb, ub)  # a fresh HiGHS model (the HighsLp-free path)
    x_warm = warm.solve(c1, a1, b1, b1, lb, ub)  # starts from the first LP's basis
    assert x_cold is not None and x_warm is not None
    # the same optimal value and a point of the same LP (a degenerate LP may pick another
    # vertex: the fuel LP's bang-bang optima often tie)
    assert c1 @ x_warm == pytest.approx(c1 @ x_cold, rel=1e-7, abs=1e-9)
    np.testing.assert_allclose(a1 @ x_warm, b1, atol=1e-7)
    np.testing.assert_allclose(a1 @ x_cold, b1, atol=1e-7)
    fresh = LPSolver(warm=False)
    fresh.solve(c1, a1, b1, b1, lb, ub)
    cold_its = fresh.iterations
    assert warm.iterations <= cold_its


def test_the_warm_lp_re_plan_gives_the_cold_plans_fuel() -> None:
    pb, res = _reserve_problem(1)
    warm = LPSolver(warm=True)
    p = res.thrust
    for k in range(1, 6):  # five LPs, each at 0.1 s more time-to-go
        g = pb.grid(res.time_of_flight + 0.1 * k)
        p_warm = fuel_lp_plan(pb, g, p, 1, warm, 10)
        p_cold = fuel_lp_plan(pb, g, p, 1, LPSolver(warm=False), 10)
        assert p_warm is not None and p_cold is not None
        f_warm, f_cold = pb.fly(p_warm, g).fuel, pb.fly(p_cold, g).fuel
        assert f_warm == pytest.approx(f_cold, rel=1e-6)
        p = p_cold


def test_kkt_tridiagonal_solve_is_the_banded_solve() -> None:
    rng = np.random.default_rng(0)
    n = 30
    g = ocp.Problem(np.zeros(3) + 1000.0, np.zeros(3), 1800.0, "energy", n).grid(40.0)
    q_main, q_upper = g.hessian_diagonals()
    jac = rng.normal(size=(6, 3, n))
    rhs = rng.normal(size=6)
    act = rng.choice([-1, 0, 0, 0, 1], size=(3, n)).astype(np.int8)
    p_b = np.where(act > 0, 1.0, np.where(act < 0, -1.0, 0.0))
    p, lam = _kkt_solve(q_main, q_upper, jac, rhs, act, p_b)
    # reference: the same Schur complement with scipy's banded solver
    free = (act == 0).astype(float)
    jt = jac.transpose(1, 2, 0)
    tri = q_main * p_b
    tri[..., :-1] += q_upper * p_b[..., 1:]
    tri[..., 1:] += q_upper * p_b[..., :-1]
    r = np.concatenate([(free * tri)[..., None], free[..., None] * jt], -1)
    x = np.empty((3, n, 7))
    for ax in range(3):
        f = free[ax]
        ab = np.zeros((3, n))
        off = q_upper * f[:-1] * f[1:]
        ab[0, 1:], ab[1], ab[2, :-1] = off, q_main * f + (1.0 - f), off
        x[ax] = solve_banded((1, 1), ab, r[ax])
    sc = 0.5 * np.einsum("oan,anp->op", jac, x[..., 1:])
    lam_ref = np.linalg.solve(sc, np.einsum("oan,an->o", jac, p_b - x[..., 0]) - rhs)
    p_ref = p_b - x[..., 0] - 0.5 * np.einsum("anp,p->an", x[..., 1:], lam_ref)
    np.testing.assert_allclose(p, p_ref, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(lam, lam_ref, rtol=1e-9, atol=1e-9)


@pytest.mark.timeout(300)
def test_envelope_plan_stays_inside_the_layers_limit_and_costs_more_than_the_reserve() -> None:
    pb, res = _reserve_problem(0)
    env = BrakeEnvelope(BRAKE_MARGIN, T_MAX_N, LAND_SPEED_MPS, 0.0, 0.0, 1)
    # the 0.9 reserve optimum counts on the lighter mass it brakes with: outside the limit
    assert envelope_excess(pb, pb.grid(res.time_of_flight), res.thrust, env) > 1.0
    out = envelope_fuel_plan(pb, res.thrust, res.time_of_flight, env, LPSolver(), 10)
    assert out is not None
    p, t_f = out
    g = pb.grid(t_f)
    assert envelope_excess(pb, g, p, env) <= 0.05
    fl = pb.fly(p, g)
    assert np.abs(fl.xf).max() <= 0.5 and np.abs(fl.vf).max() <= 0.1
    assert t_f > res.time_of_flight and fl.fuel > res.fuel
    assert np.all(p[:, 2] <= 0.9 * T_MAX_N + 1e-6)
    assert DEFAULT_ACTIONS.limits.hi[2] == T_MAX_N


@pytest.mark.timeout(300)
def test_counting_the_mass_lost_while_braking_lets_a_cheaper_plan_inside() -> None:
    """The limit of issue 68 (`pd_core.envelope`, mass loss) is wider than the limit at the mass
    now: the 0.9 reserve optimum overshoots it by less, and the cheapest plan found inside it
    burns less than inside the old one, still no less than the reserve optimum."""
    pb, res = _reserve_problem(0)
    old = BrakeEnvelope(BRAKE_MARGIN, T_MAX_N, LAND_SPEED_MPS, 0.0, 0.0, 1)
    new = BrakeEnvelope(BRAKE_MARGIN, T_MAX_N, LAND_SPEED_MPS, 0.0, 0.0, 1, mass_loss=True)
    g = pb.grid(res.time_of_flight)
    assert envelope_excess(pb, g, res.thrust, new) < envelope_excess(pb, g, res.thrust, old)
    fuel = {}
    for name, env in (("old", old), ("new", new)):
        out = envelope_fuel_plan(pb, res.thrust, res.time_of_flight, env, LPSolver(), 10)
        assert out is not None
        fl = pb.fly(out[0], pb.grid(out[1]))
        assert envelope_excess(pb, pb.grid(out[1]), out[0], env) <= 0.05
        fuel[name] = fl.fuel
    assert res.fuel - 1e-6 <= fuel["new"] < fuel["old"]


def test_lateral_settle_ends_the_horizontal_motion_before_the_plan_ends() -> None:
    pb, res = _reserve_problem(2)
    g = pb.grid(res.time_of_flight)
    free = fuel_lp_plan(pb, g, res.thrust, 8, LPSolver(), 10)
    settled = fuel_lp_plan(pb, g, res.thrust, 8, LPSolver(), 10, lateral_settle_s=2.0)
    assert free is not None and settled is not None
    t_ctrl = np.linspace(0.0, g.t_f, pb.n_control)
    last = t_ctrl >= g.t_f - 2.0
    assert np.abs(free[last, 0:2]).max() > 100.0  # the optimum brakes sideways at the end
    assert np.all(settled[last, 0:2] == 0.0)
    fl = pb.fly(settled, g)
    assert np.abs(fl.xf).max() <= 0.5 and np.abs(fl.vf).max() <= 0.1
    # at rest sideways over the pad from the first held point on, for under 1 % more fuel
    states, times = pb.simulate(settled, g.t_f)
    before_end = times >= t_ctrl[last][0]
    assert 0.0 <= t_ctrl[last][0] - (g.t_f - 2.0) < t_ctrl[1]  # within one control spacing
    assert np.abs(states[before_end, 0:2]).max() < 0.5
    assert np.abs(states[before_end, 3:5]).max() < 0.1
    assert fl.fuel < 1.01 * pb.fly(free, g).fuel


def test_time_to_rest_is_an_even_brake_to_the_gate() -> None:
    s = np.array([0.0, 0.0, 4.5, 1.0, 0.0, -2.0, 1800.0])
    assert time_to_rest_s(s, 0.5) == pytest.approx(4.0)  # 2 x 4 m / 2 m/s
    assert time_to_rest_s(s, 5.0) == 0.0  # below the gate: now
    climbing = s.copy()
    climbing[5] = 0.5
    assert time_to_rest_s(climbing, 0.5) == np.inf


def test_state_handover_answers_the_same_from_a_state_whatever_the_plan() -> None:
    """With `handover_from_state` the fallback's answer near the pad depends on the state alone:
    a cold teacher and one that has flown a whole plan to the same state agree with the law."""
    ctl = make_controller("mpc-fuel-reserve-state")
    assert isinstance(ctl, MPCController) and ctl.params.handover_from_state
    law = ctl.fallback
    # 2.3 m above the gate at 2.8 m/s: 1.6 s to rest, inside the 2 s hand-over
    near = np.array([-3.0, 0.0, 2.8, 2.5, 0.0, -2.8, 1750.0])
    assert time_to_rest_s(near, ctl.params.gate_altitude_m) < ctl.params.terminal_time_s
    assert ctl.first_action(near) == int(law.act_batch(near[None])[0])
    # the reserve teacher's own rule keys the hand-over on its plan's clock, so from the same
    # state cold it plans on (here: coasts towards the pad), where the law brakes
    old = make_controller("mpc-fuel-reserve")
    lv = DEFAULT_ACTIONS.level_table
    assert lv[old.first_action(near)][0] == 3 and lv[ctl.first_action(near)][0] < 3
