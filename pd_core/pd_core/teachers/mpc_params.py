"""Settings of the receding-horizon optimal-control teacher (`MPCParams`): a plain frozen
dataclass that imports nothing of the optimal-control stack, so that the registry of controllers
(`pd_core.teachers.registry`) can name its teachers' settings without loading a solver; the
teacher itself (`pd_core.teachers.mpc.MPCController`, which imports the solvers) loads only when
one is built."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MPCParams:
    """Settings of the receding-horizon teacher (ours; chosen on Table 1/3, see bench/mpc_speed)."""

    objective: str = "fuel"  # "energy" (Eq. 4) or "fuel"
    control_spacing_s: float = 1.0  # plan control points per second of time-to-go
    min_control_points: int = 4
    max_control_points: int = 40
    passes: int = 1  # SQP (energy) or LP (fuel) passes per warm re-plan
    # fuel LPs start from the last LP's optimal basis: 17 -> 15 simplex iterations, no faster
    # (bench/mpc_speed.py --lp), and a tied optimum may change vertex: off
    warm_lp: bool = False
    # plans use this fraction of the RL thrust limits: the rest is authority to correct the
    # quantisation and the disturbance (a fuel-optimal plan brakes at its limit to the end)
    plan_thrust_fraction: float = 0.9
    # the vertical axis's fraction where it differs (None: plan_thrust_fraction): the reserve
    # the runtime layer's braking limit counts on is a vertical one (RulesConfig.thrust_margin)
    vertical_thrust_fraction: float | None = None
    # quantise within the runtime layer's braking limit (`pd_core.runtime.rules.brake_mask` at
    # the default RulesConfig, full thrust delivered): a vertical level the limit would raise
    # is raised here, so the layer and the teacher agree (see `brake_limited`)
    keep_brake_limit: bool = False
    # ... that limit counting on the mass lost while braking (`RulesConfig.brake_mass_loss`,
    # issue 68): raise where `brake_limited(..., mass_loss=True)` fires (off: the limit at the
    # mass now, as every teacher flew before)
    brake_mass_loss: bool = False
    # ... and on the fraction of the vertical thrust the runtime layer counts on this step
    # (`Decision.thrust_gain_bound`: the identified gain, at most `unmeasured_thrust` until
    # measured), which a `Runtime` hands to an actor that takes it (`take_thrust_fraction`);
    # off, or flown without the layer: full thrust delivered, as before
    layer_thrust_fraction: bool = False
    # fuel plans keep this far (m/s) inside that braking limit (`ocp.fuel.BrakeEnvelope`,
    # elastic, on the fraction counted on and, with `brake_mass_loss`, the mass lost while
    # braking) instead of only quantising inside it; None: off (the plans as before)
    plan_brake_margin_mps: float | None = None
    # plans end at rest this high above the pad (a "low gate"): rest exactly on the pad at t_f
    # asks for infinite precision at t_f -> 0, and a plan that brakes at its limit to the
    # ground leaves nothing for the quantisation and the disturbance
    gate_altitude_m: float = 2.0
    terminal_time_s: float = 1.0  # below this time-to-go the fallback law lands
    # fuel plans hold the horizontal thrust at 0 over their last this many seconds, so the
    # horizontal motion ends before the fallback lands (a fuel-optimal plan brakes it last,
    # in the seconds the fallback flies); 0: off (see `fuel_lp_plan`)
    lateral_settle_s: float = 0.0
    terminal_altitude_m: float = 0.5  # ... or below this height above the gate
    # the time-to-go above is the state's (`time_to_rest_s`: braking evenly to rest at the
    # gate), not the plan's: the hand-over is then a function of the state a student sees
    handover_from_state: bool = False
    # "eq5" (reference carried), "eq5-replan" (reference reset each step) or "nearest" (the
    # nearest level, not the paper's; measured beside them in bench/mpc_speed.py)
    rounding: str = "eq5"
    reference_clip_mps: float = 1.0  # |v* - v| carried into Eq. 6 at most (anti-windup)
    floor_every: int = 10  # fuel plans keep z >= gate at every 10th step (and the last 10)
    # a plan dipping more than this below the gate (between the floor's steps, or an energy
    # plan) is refused: 2 m below the gate is the ground
    underground_m: float = 2.0
    tf_step_s: float = 0.4  # t_f trial step of the warm re-plans (0: the known time-to-go only)
    tf_trial_every: int = 2  # ... tried on every this many re-plans (each trial is a 2nd solve)
    # warm re-plans tried in order, (full RL limits?, extra time s): the known time-to-go
    # within the margin, then the margin spent (a plan at its limit that the lander fell
    # behind), then more time
    recovery: tuple[tuple[bool, float], ...] = ((False, 0.0), (True, 0.0), (True, 1.0), (True, 3.0))
    # a state continues a plan when it is within these of the plan's prediction (navigation
    # noise of the `nav-noise` dispersion: 1 m, 10 kg; disturbance: millimetres)
    continuity_m: float = 5.0
    continuity_mps: float = 2.0
    continuity_kg: float = 50.0
