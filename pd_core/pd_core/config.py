"""Every constant of the paper, in one place, cited by equation, section or table.

Units are SI unless a name says otherwise. Values marked "ours" are not in the paper: the paper is
silent there and we chose them (the reason is next to each).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# --- Physics (Eqs. 1-3, Sec. 2.1) -------------------------------------------------------------

GRAVITY_MPS2 = np.array([0.0, 0.0, -3.72])  # g, Mars, Eq. 2
ISP_S = 210.0  # specific impulse of each thruster, Eq. 3
G0_MPS2 = 9.81  # reference gravity, Eq. 3
DT_S = 0.2  # integration step and control period, Sec. 3
DRY_MASS_KG = (
    1000.0  # ours: the paper is silent; engines cut out at this mass (max fuel seen 690 kg)
)


@dataclass(frozen=True)
class ThrustLimits:
    """Per-axis thrust bounds in newtons, i (downrange), j (crossrange), k (up)."""

    min_n: tuple[float, float, float]
    max_n: tuple[float, float, float]

    @property
    def lo(self) -> np.ndarray:
        return np.array(self.min_n, dtype=float)

    @property
    def hi(self) -> np.ndarray:
        return np.array(self.max_n, dtype=float)


OCP_THRUST = ThrustLimits((-11e3, -11e3, 0.0), (11e3, 11e3, 12e3))  # Sec. 3.1
RL_THRUST = ThrustLimits((-10e3, -10e3, 0.0), (10e3, 10e3, 13e3))  # Sec. 4.1, Eq. 12 T_max


# --- Optimal control problem (Eq. 4, Sec. 3.1) ------------------------------------------------

OCP_CONTROL_POINTS = 80  # per axis; 3 * 80 + t_f = 241 variables, Sec. 3.1

# --- Action discretisation (Sec. 2.2, 4.2) ----------------------------------------------------

N_ACTIONS_PER_AXIS = (7, 7, 3)  # n_i = n_j = 7, n_k = 3, Table 6 / Sec. 4.2 -> 147 actions
TABLE5_N_IJ = (3, 5, 7, 9, 11)  # Table 5 rows
TABLE5_N_K = (2, 3, 4, 5, 6, 7, 8, 9, 10)  # Table 5 columns

# --- Reward (Eqs. 12-18, Sec. 3.2) ------------------------------------------------------------


@dataclass(frozen=True)
class RewardConfig:
    """Coefficients and limits of the shaped reward, Eq. 12-18."""

    alpha: float = -0.01  # velocity-error weight, Sec. 3.2
    beta: float = -0.05  # control-effort weight, Sec. 3.2
    eta: float = 0.01  # per-step bonus, Sec. 3.2
    kappa: float = 10.0  # landing bonus, Sec. 3.2
    # ours (0: the paper): on landing, + this * (1 - |r_ij| / x_lim). Eq. 12's bonus is flat
    # inside 5 m and below 15 m Eq. 13 aims the lateral velocity at 0, not at the pad, so the
    # paper's reward has no gradient towards a miss under a few metres.
    precision_bonus: float = 0.0
    v0_mps: float = 70.0  # Eq. 14
    altitude_switch_m: float = 15.0  # Eqs. 16-18 branch
    r_offset_m: float = 15.0  # Eq. 16, r_hat = x - [0 0 15] above the switch
    v_offset_high_mps: float = -2.0  # Eq. 17 above the switch
    v_offset_low_mps: float = -1.0  # Eq. 17 below the switch
    tau_high_s: float = 20.0  # Eq. 18 above the switch
    tau_low_s: float = 100.0  # Eq. 18 below the switch
    touchdown_altitude_m: float = 0.01  # r_z < 0.01, Eq. 12 and Sec. 4.2
    x_lim_m: float = 5.0  # Eq. 12
    v_lim_mps: float = 2.0  # Eq. 12
    # ours: |v_hat| below this is treated as this, so t_go (Eq. 15) stays finite; the target
    # velocity then saturates at v0 (1 - exp(-t_go/tau)) -> v0, the limit of Eq. 13.
    min_speed_mps: float = 1e-6
    # ours: |r_hat| below this gives a zero direction in Eq. 13 instead of 0/0.
    min_range_m: float = 1e-9


REWARD = RewardConfig()

# --- Disturbance (Sec. 3.2) -------------------------------------------------------------------


@dataclass(frozen=True)
class DisturbanceConfig:
    """Gaussian force per axis, sampled every second and linearly interpolated, Sec. 3.2."""

    sigma_n: float = 100.0
    mean_n: float = 0.0
    knot_interval_s: float = 1.0


DISTURBANCE = DisturbanceConfig()

# --- Initial conditions (Tables 1 and 3) ------------------------------------------------------


@dataclass(frozen=True)
class StateRange:
    """Box of initial states [x, y, z, vx, vy, vz, m] (m, m/s, kg)."""

    low: tuple[float, ...]
    high: tuple[float, ...]

    @property
    def lo(self) -> np.ndarray:
        return np.array(self.low, dtype=float)

    @property
    def hi(self) -> np.ndarray:
        return np.array(self.high, dtype=float)


TABLE1 = StateRange(  # optimal trajectories, Table 1
    (500.0, -1000.0, 2500.0, -70.0, -30.0, -90.0, 2000.0),
    (1000.0, 1000.0, 2500.0, -10.0, 30.0, -70.0, 2000.0),
)
TABLE3 = StateRange(  # RL training and testing, Table 3
    (400.0, -1100.0, 2400.0, -75.0, -35.0, -95.0, 2000.0),
    (1100.0, 1100.0, 2600.0, -5.0, 35.0, -65.0, 2000.0),
)

# --- State scaling (Eqs. 20-21) ---------------------------------------------------------------

STATE_SCALE = np.array([0.01, 0.01, 0.01, 0.1, 0.1, 0.1, 0.005])  # Eq. 21
# ours: length scales (m, m, m, m/s, m/s, m/s) of the near-pad inputs a network may add to Eq. 21
# (pd_core.state.near_pad_features): at Eq. 21's 0.01/m a 0.5 m miss moves the input by 0.005, and
# the student disagreed with its teacher on 41 % of the lateral choices of the last 5 m
# (models/pd_dqn_robust.md, "Near-pad inputs")
NEAR_PAD_SCALE = np.array([2.0, 2.0, 10.0, 0.5, 0.5, 2.0])
# ours (issue 68): span of the thrust input a network may add to Eq. 21, the vertical thrust
# fraction the runtime layer counts on, as (1 - fraction) / span: 0 on a nominal engine, 1 on the
# weakest engine promised (80 %); pd_core.state.thrust_input
THRUST_INPUT_SPAN = 0.2

# --- Braking (ours: the ZEM/ZEV teacher's profile and the runtime layer's braking limit) ------

BRAKE_MARGIN = 0.9  # fraction of the vertical braking authority counted on (thrust error, gusts)
LAND_SPEED_MPS = 0.5  # descent speed aimed at on the pad (Eq. 12 allows 2 m/s; see controllers)
# ours: the runtime layer lets a lander touch down this fast (half of Eq. 12's 2 m/s)
TOUCHDOWN_SPEED_MPS = 1.0
GUARD_ALTITUDE_M = 10.0  # ours: no free fall below this while descending (pd_core.runtime.rules)
# ours: where the guard's raised level would climb faster than this, it lets a lander descending
# slower than the land speed fall freely (pd_core.runtime.rules: the hover trap of light landers)
GUARD_CLIMB_MPS2 = 1.0
HANDOVER_ALTITUDE_M = 5.0  # ours: above this the layer hands lateral-limited states to the teacher
# ours: below this (observed) mass the teacher flies: lighter than the student was trained to land
# (its lightest training starts, 1600 kg, touch down at about 1300-1350 kg; pd_core.runtime.rules)
HANDOVER_MASS_KG = 1350.0
MAX_DELAY_STEPS = (
    8  # ours: longest actuation delay (1.6 s) identified in flight (pd_core.runtime.latency)
)

# --- Episodes (Sec. 4.2) ----------------------------------------------------------------------

# ours: truncation (not termination) after this long; the slowest landings of Table 3 take
# about 70 s, so 150 s leaves room for hovering policies without running out of fuel first.
MAX_EPISODE_TIME_S = 150.0

# --- DQN (Table 2, Sec. 2.3 and 3.2) ----------------------------------------------------------


@dataclass(frozen=True)
class DQNPaper:
    """Hyperparameters of Table 2."""

    hidden: tuple[int, int, int] = (300, 200, 300)
    learning_rate: float = 1e-5
    epsilon0: float = 0.6
    epsilon_episodes: int = 4000
    gamma: float = 0.926
    batch_agent: int = 100  # k
    batch_demo: int = 100  # k_demo
    target_period_steps: int = 65  # n_T
    episodes: int = 10_000  # Sec. 3.2
    batch_agent_no_demo: int = 200  # Agent 2, Sec. 3.2
    eval_episodes: int = 1000  # Sec. 3.2


DQN_PAPER = DQNPaper()

# --- Paper results, for side-by-side printing (Tables 4-7) ------------------------------------

PAPER_TABLE4 = {  # optimal trajectories: (median, min, max)
    "norm_ij_position_m": (0.015, 5.6e-4, 0.259),
    "k_position_m": (0.016, -0.043, 0.240),
    "norm_ij_velocity_mps": (3.5e-4, 1.8e-5, 0.011),
    "k_velocity_mps": (1.7e-4, -9.3e-3, 7.8e-3),
    "fuel_kg": (415.9, 291.0, 550.5),
    "T1_n": (621.0, -3331.0, 9320.0),
    "T2_n": (-36.0, -7415.0, 7557.0),
    "T3_n": (8592.0, 1292.0, 12000.0),
}
PAPER_TABLE5 = {  # % successful discretised episodes, rows n_ij, columns n_k = 2..10
    3: (48.5, 78.8, 30.3, 63.6, 24.2, 57.6, 0.0, 48.5, 3.0),
    5: (42.4, 75.8, 24.2, 66.7, 21.2, 54.5, 0.0, 42.4, 3.0),
    7: (39.4, 81.8, 33.3, 66.7, 21.2, 54.5, 0.0, 45.5, 3.0),
    9: (51.5, 81.8, 33.3, 66.7, 24.2, 54.5, 0.0, 42.4, 3.0),
    11: (30.3, 78.8, 30.3, 60.6, 21.2, 51.5, 0.0, 42.4, 3.0),
}
PAPER_TABLE6 = {  # discretised (7, 7, 3) trajectories at their final state
    "norm_ij_position_m": (1.7e-5, 2e-7, 178.3),
    "k_position_m": (-8.4e-5, -1.3, 2.6e-4),
    "norm_ij_velocity_mps": (0.384, 2.8e-3, 22.2),
    "k_velocity_mps": (-0.471, -23.7, -0.027),
    "fuel_kg": (407.9, 276.1, 503.2),
}
PAPER_TABLE7 = {  # evaluation over 1000 episodes, (median, min, max)
    "agent1": {
        "norm_ij_position_m": (6.04, 0.255, 51.4),
        "norm_ij_velocity_mps": (0.427, 2.4e-4, 4.86),
        "k_velocity_mps": (-0.691, -9.78, 1.28),
        "fuel_kg": (495.9, 419.4, 690.1),
    },
    "agent2": {
        "norm_ij_position_m": (3.37, 0.151, 8.81),
        "norm_ij_velocity_mps": (1.58, 0.185, 3.81),
        "k_velocity_mps": (-14.1, -15.0, -11.8),
        "fuel_kg": (335.9, 277.6, 413.7),
    },
}
