"""Shaped reward of Eqs. 12-18, batched over leading axes.

Computed on the state after a step and the thrust applied during it. Two guards keep it finite
where the paper's formula is 0/0: t_go = |r_hat| / max(|v_hat|, min_speed) (Eq. 15; a lander at
rest relative to v_hat gets the saturated target speed v0, the limit t_go -> inf of Eq. 13) and
r_hat / max(|r_hat|, min_range) (Eq. 13; on the pad the target velocity is 0).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pd_core.config import REWARD, RL_THRUST, RewardConfig


def _norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norm over the last axis (3x faster than np.linalg.norm on (N, 3))."""
    return np.sqrt(np.einsum("...i,...i->...", v, v))


def target_velocity(
    position_m: np.ndarray, velocity_mps: np.ndarray, cfg: RewardConfig = REWARD
) -> np.ndarray:
    """Target velocity of Eq. 13 (m/s), (..., 3), with Eqs. 14-18 for both altitude branches."""
    z = position_m[..., 2]
    high = z > cfg.altitude_switch_m
    r_hat = np.zeros_like(position_m)
    r_hat[..., 2] = np.where(high, z - cfg.r_offset_m, z)
    r_hat[..., 0:2] = np.where(high[..., None], position_m[..., 0:2], 0.0)
    v_hat = velocity_mps.copy()
    v_hat[..., 2] -= np.where(high, cfg.v_offset_high_mps, cfg.v_offset_low_mps)
    tau = np.where(high, cfg.tau_high_s, cfg.tau_low_s)
    r_norm = _norm(r_hat)
    t_go = r_norm / np.maximum(_norm(v_hat), cfg.min_speed_mps)
    gain = -cfg.v0_mps * (1.0 - np.exp(-t_go / tau)) / np.maximum(r_norm, cfg.min_range_m)
    return gain[..., None] * r_hat


def landing_bonus(miss_ij_m: Any, cfg: RewardConfig = REWARD) -> Any:
    """Bonus of a landing `miss_ij_m` (m, float or array) from the pad: kappa (Eq. 12), plus the
    optional `precision_bonus` (ours, 0 in the paper) that rises towards the pad."""
    return cfg.kappa + cfg.precision_bonus * (1.0 - miss_ij_m / cfg.x_lim_m)


def landed(
    position_m: np.ndarray, velocity_mps: np.ndarray, cfg: RewardConfig = REWARD
) -> np.ndarray:
    """The kappa condition of Eq. 12: altitude < 0.01 m, |x| < 5 m, |v| < 2 m/s."""
    return (
        (position_m[..., 2] < cfg.touchdown_altitude_m)
        & (_norm(position_m) < cfg.x_lim_m)
        & (_norm(velocity_mps) < cfg.v_lim_mps)
    )


def missed_limits(
    position_m: np.ndarray, velocity_mps: np.ndarray, cfg: RewardConfig = REWARD
) -> tuple[np.ndarray, np.ndarray]:
    """(off the pad, too fast): which of Eq. 12's touchdown limits (|x| < 5 m, |v| < 2 m/s) a
    state misses, so every report of a failed landing gives the same reason."""
    return _norm(position_m) >= cfg.x_lim_m, _norm(velocity_mps) >= cfg.v_lim_mps


def reward(
    position_m: np.ndarray,
    velocity_mps: np.ndarray,
    thrust_n: np.ndarray,
    cfg: RewardConfig = REWARD,
    thrust_max_n: np.ndarray | None = None,
    landed_mask: np.ndarray | None = None,
) -> np.ndarray:
    """Eq. 12, elementwise T / T_max with T_max the RL limits of Sec. 4.1 by default.

    Pass `landed_mask` when the kappa condition is already computed.
    """
    t_max = RL_THRUST.hi if thrust_max_n is None else thrust_max_n
    v_err = _norm(velocity_mps - target_velocity(position_m, velocity_mps, cfg))
    effort = _norm(thrust_n / t_max)
    ok = landed(position_m, velocity_mps, cfg) if landed_mask is None else landed_mask
    bonus = np.where(ok, landing_bonus(_norm(position_m[..., 0:2]), cfg), 0.0)
    return cfg.alpha * v_err + cfg.beta * effort + cfg.eta + bonus


def reward_scalar(
    state: tuple[float, ...],
    thrust_n: tuple[float, float, float],
    cfg: RewardConfig = REWARD,
    thrust_max_n: tuple[float, float, float] | None = None,
) -> tuple[float, bool]:
    """(Eq. 12 reward, kappa condition) for one state (7,) on Python floats; equals `reward`."""
    x, y, z, vx, vy, vz = state[:6]
    if z > cfg.altitude_switch_m:
        rx, ry, rz = x, y, z - cfg.r_offset_m
        wz, tau = vz - cfg.v_offset_high_mps, cfg.tau_high_s
        wx, wy = vx, vy
    else:
        rx, ry, rz = 0.0, 0.0, z
        wz, tau = vz - cfg.v_offset_low_mps, cfg.tau_low_s
        wx, wy = vx, vy
    r_norm = math.sqrt(rx * rx + ry * ry + rz * rz)
    t_go = r_norm / max(math.sqrt(wx * wx + wy * wy + wz * wz), cfg.min_speed_mps)
    gain = -cfg.v0_mps * (1.0 - math.exp(-t_go / tau)) / max(r_norm, cfg.min_range_m)
    ex, ey, ez = vx - gain * rx, vy - gain * ry, vz - gain * rz
    mx, my, mz = thrust_max_n if thrust_max_n is not None else _RL_MAX
    fx, fy, fz = thrust_n[0] / mx, thrust_n[1] / my, thrust_n[2] / mz
    speed = math.sqrt(vx * vx + vy * vy + vz * vz)
    ok = (
        z < cfg.touchdown_altitude_m
        and math.sqrt(x * x + y * y + z * z) < cfg.x_lim_m
        and speed < cfg.v_lim_mps
    )
    bonus = landing_bonus(math.sqrt(x * x + y * y), cfg) if ok else 0.0
    r = (
        cfg.alpha * math.sqrt(ex * ex + ey * ey + ez * ez)
        + cfg.beta * math.sqrt(fx * fx + fy * fy + fz * fz)
        + cfg.eta
        + bonus
    )
    return r, ok


_RL_MAX = tuple(float(v) for v in RL_THRUST.hi)
