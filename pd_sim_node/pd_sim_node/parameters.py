"""pd_sim_node's parameters: name, typed default and description of each (`PARAMETERS`, read at
start-up, read-only afterwards; defaults in pd_bringup/config/sim.yaml), their range checks
(`CHECKS`, for `pd_ros_common.params.declare`), the old meaning of `autostart` kept for one
release (`old_autostart`), the `Simulator` they configure (`make_simulator`) and the line that
says so (`ready_line`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

from pd_core.config import DT_S, MAX_EPISODE_TIME_S
from pd_core.sim import (
    MAX_NAV_SIGMA,
    MAX_SIM_DELAY_STEPS,
    MISSING_COMMAND_MODES,
    THRUST_SCALE_RANGE,
    Simulator,
)
from pd_ros_common import params
from pd_ros_common.lifecycle import AUTOSTART

# name: (default, description); every one is read at start-up.
PARAMETERS: dict[str, tuple[Any, str]] = {
    "rate_hz": (
        1.0 / DT_S,
        "Real-time mode: steps (and lander/state messages) per second of wall clock. "
        "5.0 = real time (one dt = 0.2 s per message). Ignored in lockstep.",
    ),
    "lockstep": (
        False,
        "Step only when the command answering the current step has arrived (as fast as the "
        "policy answers, deterministic) instead of on the wall clock.",
    ),
    "resend_s": (
        1.0,
        "Publish the current state again after this many seconds without an answer: in "
        "lockstep, and in real time while an episode waits for its first command (0 = never).",
    ),
    "start_wait_s": (
        -1.0,
        "Real time: an episode started at start-up or by sim/reset starts its clock when the "
        "first command answering step 0 arrives: -1 = however long that takes, > 0 = at most "
        "this many seconds (then it flies without commands, with a warning), 0 = at once.",
    ),
    "missing_command": (
        "hold",
        "What a step without a fresh valid command flies: 'hold' (the last applied command of "
        "the episode; zero thrust before the first) or 'zero' (zero thrust).",
    ),
    "seed": (
        0,
        "Seed of the first episode (initial state and disturbance); later episodes continue "
        "the RNG unless sim/reset reseeds. -1 = unseeded.",
    ),
    "disturbance": (True, "Apply the random disturbance force of Sec. 3.2 (sigma 100 N)."),
    "autostart": (
        AUTOSTART[0],
        AUTOSTART[1] + " Deprecated old meaning, for this release only: given as false "
        "without start_episode, it is read as start_episode:=false (and the node starts "
        "active), with a warning.",
    ),
    "start_episode": (
        True,
        "Start the first episode when the node is configured (from initial_state, or Table 3 "
        "with seed); it flies once the node is active. false = wait for sim/reset. (Called "
        "autostart before the nodes were managed.)",
    ),
    "auto_restart": (
        False,
        "When an episode ends, start the next one (Table 3, RNG continued): one period later "
        "in real time, at once in lockstep; false = publish the result and wait for sim/reset.",
    ),
    "initial_state": (
        [0.0],
        "[x, y, z, vx, vy, vz, m] (m, m/s, kg) of the first episode (start_episode); any "
        "other length (default [0.0]) = sample Table 3.",
    ),
    "max_time_s": (
        MAX_EPISODE_TIME_S,
        "Simulation time after which an episode ends OUT_OF_TIME (truncated).",
    ),
    "tick_priority": (
        0,
        "Real-time mode: > 0 runs the clock thread under SCHED_FIFO at this priority (Linux, "
        "needs CAP_SYS_NICE; lowers period jitter on a busy machine); 0 = normal scheduling.",
    ),
    "log_rejections": (
        20,
        "Rejected commands logged one by one per episode; after that every 100th (all are "
        "counted in EpisodeResult.rejected_commands).",
    ),
    "delay_steps": (
        0,
        "Actuation delay for latency tests: the lander flies the command of this many steps "
        "(0.2 s each) earlier, zero thrust before the first (as pd-eval's delay_steps "
        "dispersion). 0 = none.",
    ),
    "nav_position_sigma_m": (
        0.0,
        "Navigation noise for filter tests: white Gaussian noise (m, per axis, drawn each step) "
        "on the published position, as pd-eval's nav_position_sigma_m dispersion. The episode "
        "result keeps the true state. 0 = none.",
    ),
    "nav_velocity_sigma_mps": (
        0.0,
        "As nav_position_sigma_m, on the published velocity (m/s). 0 = none.",
    ),
    "thrust_scale": (
        1.0,
        "Engine out of spec, for thrust-error tests: every thruster delivers this fraction of "
        "the commanded thrust (0.85 = 15 % short), as a fixed pd-eval thrust_error. 1 = none.",
    ),
    "command_source": (
        "",
        "Name of the one node whose thrust commands fly (e.g. pd_policy_node): commands from "
        "any other publisher, or one the ROS graph cannot name yet, are rejected as foreign and "
        "counted, even when they answer a step first. Empty = any publisher (first command "
        "wins).",
    ),
    "lander_id": (
        "",
        "Identity of this simulator run, carried by every lander/state and echoed by the "
        "commands answering it; commands for another id are counted as foreign and never "
        "flown. Empty = a random 8-hex-digit id at start-up.",
    ),
    "path_period_s": (
        1.0,
        "Publish lander/path (nav_msgs/Path of the episode so far) every this many seconds "
        "of wall clock while flying; it is always published when an episode ends. 0 = only then.",
    ),
}

CHECKS: dict[str, params.Check] = {
    "rate_hz": params.above(0.0),
    "resend_s": params.at_least(0.0),
    "start_wait_s": lambda v: None if v == -1 or v >= 0 else "must be -1 (no limit) or >= 0",
    "missing_command": params.one_of(MISSING_COMMAND_MODES),
    "seed": params.at_least(-1),
    "max_time_s": params.at_least(DT_S),
    "tick_priority": params.at_least(0),
    "delay_steps": lambda v: (
        None if 0 <= v <= MAX_SIM_DELAY_STEPS else f"must be in [0, {MAX_SIM_DELAY_STEPS}]"
    ),
    "log_rejections": params.at_least(0),
    "nav_position_sigma_m": lambda v: (
        None if 0.0 <= v <= MAX_NAV_SIGMA[0] else f"must be in [0, {MAX_NAV_SIGMA[0]:g}]"
    ),
    "nav_velocity_sigma_mps": lambda v: (
        None if 0.0 <= v <= MAX_NAV_SIGMA[1] else f"must be in [0, {MAX_NAV_SIGMA[1]:g}]"
    ),
    "thrust_scale": lambda v: (
        None
        if THRUST_SCALE_RANGE[0] <= v <= THRUST_SCALE_RANGE[1]
        else f"must be in [{THRUST_SCALE_RANGE[0]:g}, {THRUST_SCALE_RANGE[1]:g}]"
    ),
    "command_source": lambda v: (
        None
        if re.fullmatch(r"([A-Za-z_][A-Za-z0-9_]*)?", v)
        else "must be a node name (letters, digits, underscores) or empty"
    ),
    "lander_id": lambda v: (
        None
        if re.fullmatch(r"[A-Za-z0-9_.-]{0,64}", v)
        else "must be at most 64 letters, digits, '_', '.' or '-' (empty = random)"
    ),
    "path_period_s": params.at_least(0.0),
}

OLD_AUTOSTART = (
    "autostart:=false is read in its old meaning, start_episode:=false (deprecated, for this "
    "release only): autostart now names the lifecycle; set start_episode:=false to wait for "
    "sim/reset, and give start_episode with autostart:=false for a node that waits unconfigured"
)


def old_autostart(p: Mapping[str, Any], given: Mapping[str, Any]) -> bool:
    """True when `autostart` is given false without `start_episode` (`given`: the overrides):
    then it means start_episode:=false and an autostarted node, with the warning OLD_AUTOSTART."""
    return "autostart" in given and "start_episode" not in given and not p["autostart"]


def make_simulator(p: Mapping[str, Any], lander_id: str) -> Simulator:
    """The simulator the declared parameters `p` describe, for lander `lander_id`."""
    return Simulator(
        disturbance=p["disturbance"],
        missing_command=p["missing_command"],
        max_time_s=p["max_time_s"],
        seed=p["seed"] if p["seed"] >= 0 else None,
        command_source=p["command_source"],
        delay_steps=p["delay_steps"],
        nav_sigma=(p["nav_position_sigma_m"], p["nav_velocity_sigma_mps"]),
        thrust_scale=p["thrust_scale"],
        lander_id=lander_id,
    )


def ready_line(p: Mapping[str, Any], lander_id: str) -> str:
    """What configure says once the simulator of parameters `p` is ready."""
    mode = "lockstep" if p["lockstep"] else f"real time at {p['rate_hz']:g} Hz"
    return (
        f"simulator ready: {mode}, missing_command={p['missing_command']}, "
        f"disturbance={p['disturbance']}, seed={p['seed']}, "
        f"command_source={p['command_source'] or '(any publisher)'}, "
        f"lander_id={lander_id}"
    )
