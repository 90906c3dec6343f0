"""Equations of motion of the 3-DOF lander (Eqs. 1-3), batched over leading axes.

Integration scheme: exact integration over a step of constant force. Within a step the thrust is
constant (the RL action is held for dt; the OCP evaluates its interpolated thrust at the step's
midpoint) and the mass falls linearly (Eq. 3), so Eq. 2 integrates in closed form:

    v(t) = v0 + g t + (u t / m0) phi1(z),   x(t) = x0 + v0 t + g t^2/2 + (u t^2 / m0) phi2(z)

with u = T + F_env, z = mdot t / m0, phi1 = -ln(1 - z)/z and phi2 = (z + (1 - z) ln(1 - z))/z^2.
Both are evaluated by their power series, which has no 0/0 at zero thrust and no cancellation.
This is exact where RK4 would carry an O(dt^5) error, costs less than one RK4 stage, and is the
same function for the OCP, the environments and the simulator node.
"""

from __future__ import annotations

import numpy as np

from pd_core.config import DRY_MASS_KG, G0_MPS2, GRAVITY_MPS2, ISP_S

STATE_DIM = 7  # [x, y, z, vx, vy, vz, m]: m, m/s, kg

# Taylor coefficients of phi1(z) = sum z^(k-1)/k and phi2(z) = sum z^(k-2)/(k(k-1)), highest first
# for Horner. z = mdot dt / m stays below 0.005 at dt = 0.2 s, so 9 terms reach machine precision
# for any dt up to a few seconds.
PHI1 = tuple(1.0 / k for k in range(9, 0, -1))
PHI2 = tuple(1.0 / (k * (k - 1)) for k in range(10, 1, -1))


def horner(coeffs: tuple[float, ...], z: np.ndarray) -> np.ndarray:
    """Polynomial with `coeffs` (highest power first) at z: the phi series of `step` and the OCP."""
    out = np.full_like(z, coeffs[0])
    for c in coeffs[1:]:
        out *= z
        out += c
    return out


def mass_flow_kgps(thrust_n: np.ndarray, isp_s: float | np.ndarray = ISP_S) -> np.ndarray:
    """Fuel mass flow of Eq. 3 (kg/s), positive; thrust_n (..., 3) in N, isp_s in s (or (...,))."""
    return np.abs(thrust_n).sum(axis=-1) / (isp_s * G0_MPS2)


def derivatives(state: np.ndarray, thrust_n: np.ndarray, force_n: np.ndarray) -> np.ndarray:
    """Right-hand side of Eqs. 1-3: d/dt [x, v, m]. For checks; `step` integrates it exactly."""
    out = np.empty(np.broadcast_shapes(state.shape), dtype=float)
    out[..., 0:3] = state[..., 3:6]
    out[..., 3:6] = (thrust_n + force_n) / state[..., 6:7] + GRAVITY_MPS2
    out[..., 6] = -mass_flow_kgps(thrust_n)
    return out


def step(
    state: np.ndarray,
    thrust_n: np.ndarray,
    force_n: np.ndarray,
    dt_s: float | np.ndarray,
    dry_mass_kg: float = DRY_MASS_KG,
    isp_s: float | np.ndarray = ISP_S,
) -> np.ndarray:
    """Advance states (..., 7) by dt_s under constant thrust (..., 3) and disturbance (..., 3), N.

    `isp_s` (s, scalar or per lander (...,)) sets the mass flow of Eq. 3; dispersions vary it.

    Engines cannot burn below `dry_mass_kg`: a step that would is flown at the reduced thrust
    that ends it exactly at dry mass (same impulse direction, same fuel accounting), and a dry
    lander falls ballistically.
    """
    m0 = state[..., 6]
    dt = np.asarray(dt_s, dtype=float)
    mdot = mass_flow_kgps(thrust_n, isp_s)
    burn = mdot * dt
    fuel_left = np.maximum(m0 - dry_mass_kg, 0.0)
    if np.any(burn > fuel_left):
        scale = np.where(burn > fuel_left, fuel_left / np.where(burn > 0.0, burn, 1.0), 1.0)
        thrust_n = thrust_n * scale[..., None]
        mdot = mdot * scale
        burn = burn * scale
    z = burn / m0
    u = thrust_n + force_n
    dt_col = dt[..., None] if dt.ndim else dt
    a = u * (dt_col / m0[..., None])
    out = np.empty(np.broadcast_shapes(state.shape, u.shape[:-1] + (STATE_DIM,)), dtype=float)
    v0 = state[..., 3:6]
    gdt = GRAVITY_MPS2 * dt_col
    out[..., 0:3] = state[..., 0:3] + dt_col * (v0 + 0.5 * gdt + a * horner(PHI2, z)[..., None])
    out[..., 3:6] = v0 + gdt + a * horner(PHI1, z)[..., None]
    out[..., 6] = m0 - burn
    return out


def rollout(
    state0: np.ndarray, thrust_n: np.ndarray, force_n: np.ndarray | None, dt_s: float
) -> np.ndarray:
    """States (n+1, 7) of a run of n steps with thrust_n (n, 3) and force_n (n, 3) or None."""
    n = thrust_n.shape[0]
    states = np.empty((n + 1, STATE_DIM))
    states[0] = state0
    zero = np.zeros(3)
    for i in range(n):
        states[i + 1] = step(states[i], thrust_n[i], zero if force_n is None else force_n[i], dt_s)
    return states


def step_scalar(
    state: tuple[float, ...] | list[float],
    thrust_n: tuple[float, float, float],
    force_n: tuple[float, float, float],
    dt_s: float,
    dry_mass_kg: float = DRY_MASS_KG,
) -> tuple[float, ...]:
    """`step` for one lander on Python floats: 10x faster than numpy on 7-vectors.

    Same formulas and the same series as `step` (tests hold them equal to 1e-12); the single
    environment and the simulator node fly this one.
    """
    x, y, z_m, vx, vy, vz, m0 = state
    tx, ty, tz = thrust_n
    burn = (abs(tx) + abs(ty) + abs(tz)) / (ISP_S * G0_MPS2) * dt_s
    fuel_left = m0 - dry_mass_kg if m0 > dry_mass_kg else 0.0
    if burn > fuel_left:
        s = fuel_left / burn
        tx, ty, tz, burn = tx * s, ty * s, tz * s, fuel_left
    z = burn / m0
    p1 = PHI1[0]
    for c in PHI1[1:]:
        p1 = p1 * z + c
    p2 = PHI2[0]
    for c in PHI2[1:]:
        p2 = p2 * z + c
    k = dt_s / m0
    ax, ay, az = (tx + force_n[0]) * k, (ty + force_n[1]) * k, (tz + force_n[2]) * k
    gx, gy, gz = _G_TUPLE
    return (
        x + dt_s * (vx + 0.5 * gx * dt_s + ax * p2),
        y + dt_s * (vy + 0.5 * gy * dt_s + ay * p2),
        z_m + dt_s * (vz + 0.5 * gz * dt_s + az * p2),
        vx + gx * dt_s + ax * p1,
        vy + gy * dt_s + ay * p1,
        vz + gz * dt_s + az * p1,
        m0 - burn,
    )


_G_TUPLE = tuple(float(g) for g in GRAVITY_MPS2)
