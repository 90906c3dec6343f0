"""The braking law (ours): how fast a lander may descend at an altitude, given the vertical force
it counts on to brake and its mass. Its one home: the runtime layer's braking limit
(`pd_core.runtime.kernels_rules`, compiled), the fuel-optimal teacher's quantisation
(`pd_core.teachers.mpc`) and the benches call these functions.

Braking with a constant vertical force F (N; the layer counts on `thrust_margin` x the measured
fraction x 13 kN) from mass m (kg) under gravity g (m/s^2, > 0), to the land speed v_l (m/s) at
the pad, two limits on the descent speed at altitude z (m):

* **at the mass now** (`max_descent_speed_mps`), what every policy file before issue 68 flies:

      v_max(z, m) = sqrt(v_l^2 + 2 z (F / m - g));

* **counting on the mass lost while braking** (`max_descent_speed_mass_loss_mps`, issue 68):
  the burn's mass falls at F / v_e (Eq. 3 with the braking force alone, v_e = Isp g0: the least
  any command delivering F burns), so after t seconds of braking the lander has gained

      dv(t) = -v_e ln(1 - q t) - g t,   q = F / (v_e m),

  and descended D(t) = v(0) t - int_0^t dv. The limit is the v(0) = v_l + dv(T) of the burn of
  length T that ends at the pad at v_l: D(T) = z with

      D(T) = (v_l + dv(T)) T - v_e ((1 - qT) ln(1 - qT) / q + T) + g T^2 / 2,

  D' = v_l + T a(T) (a(T) = F / m(T) - g, the deceleration at the burn's end), D convex and
  increasing; Newton from the constant-mass burn's length (D there is >= z) converges from
  above. Where the burn would run the lander dry, the constant-mass limit answers.

`descent_limits` gives the limit and its slope along arrays (an optimiser's linearisation, the
fuel floor inside the limit: `pd_core.ocp.fuel.BrakeEnvelope`). `brake_fires` is the layer's rule
on one step: the command counted on for one step (0.2 s), then
the limit at the altitude reached; a step that ends on the ground is judged by its touchdown
speed instead. Every function is scalar Python on floats (`math` only) and `jitable`: Python
callers call it as it is, numba compiles it into the kernels that call it, the same arithmetic
in the same order (the layer flew files before issue 68 to the bit with its own copy of the
constant-mass formula; tests/unit/test_envelope.py holds the two equal).
"""

from __future__ import annotations

import math

import numpy as np

from pd_core.config import DRY_MASS_KG, G0_MPS2, ISP_S
from pd_core.jit import jitable

EXHAUST_VELOCITY_MPS = ISP_S * G0_MPS2
"""v_e = Isp g0 (m/s) of Eq. 3: mass flow = |thrust|_1 / v_e"""
NO_LIMIT, DESCENT, DESCENT_MASS_LOSS, TOUCHDOWN = 0, 1, 2, 3
"""what `brake_fires` returns: the limit that fired (`pd_core.runtime.decision.LIMITS`)"""
NEWTON_STEPS = 30
"""at most this many Newton steps on the burn's length (converges in 3-6 from a full-size
limit: tests/unit/test_envelope.py)"""


@jitable
def max_descent_speed_mps(
    altitude_m: float,
    mass_kg: float,
    braking_force_n: float,
    land_speed_mps: float,
    gravity_mps2: float,
) -> float:
    """Fastest descent (m/s, >= land speed) from which braking_force_n at the mass now brakes to
    land_speed_mps by the pad; the land speed where it cannot brake at all or z <= 0."""
    a_net = braking_force_n / mass_kg - gravity_mps2
    return math.sqrt(land_speed_mps**2 + 2.0 * max(a_net, 0.0) * max(altitude_m, 0.0))


@jitable
def max_descent_speed_mass_loss_mps(
    altitude_m: float,
    mass_kg: float,
    braking_force_n: float,
    land_speed_mps: float,
    gravity_mps2: float,
    exhaust_velocity_mps: float = EXHAUST_VELOCITY_MPS,
    dry_mass_kg: float = DRY_MASS_KG,
) -> float:
    """Fastest descent (m/s) from which braking_force_n, the mass falling at braking_force_n /
    exhaust_velocity_mps, brakes to land_speed_mps by the pad (module docstring); >= the
    constant-mass limit, equal to it where it cannot brake, z <= 0 or the burn runs dry."""
    v_l, g, v_e = land_speed_mps, gravity_mps2, exhaust_velocity_mps
    a0 = braking_force_n / mass_kg - g
    z = max(altitude_m, 0.0)
    if a0 <= 0.0 or z <= 0.0:
        return max_descent_speed_mps(altitude_m, mass_kg, braking_force_n, v_l, g)
    q = braking_force_n / (v_e * mass_kg)
    t = (math.sqrt(v_l * v_l + 2.0 * a0 * z) - v_l) / a0  # the constant-mass burn: D(t) >= z
    for _ in range(NEWTON_STEPS):
        left = 1.0 - q * t
        dv = -v_e * math.log(left) - g * t
        dist = (v_l + dv) * t - v_e * (left * math.log(left) / q + t) + 0.5 * g * t * t
        slope = v_l + t * (v_e * q / left - g)
        step = (dist - z) / slope
        t -= step
        if abs(step) <= 1e-12 * (1.0 + t):
            break
    left = 1.0 - q * t
    if mass_kg * left <= dry_mass_kg:
        return max_descent_speed_mps(altitude_m, mass_kg, braking_force_n, v_l, g)
    return v_l - v_e * math.log(left) - g * t


@jitable
def max_descent_speed_for(
    altitude_m: float,
    mass_kg: float,
    braking_force_n: float,
    land_speed_mps: float,
    gravity_mps2: float,
    mass_loss: bool,
) -> float:
    """`max_descent_speed_mass_loss_mps` where mass_loss, else `max_descent_speed_mps`."""
    if mass_loss:
        return max_descent_speed_mass_loss_mps(
            altitude_m, mass_kg, braking_force_n, land_speed_mps, gravity_mps2
        )
    return max_descent_speed_mps(altitude_m, mass_kg, braking_force_n, land_speed_mps, gravity_mps2)


def descent_limits(
    altitude_m: np.ndarray,
    mass_kg: np.ndarray,
    braking_force_n: float,
    land_speed_mps: float,
    gravity_mps2: float,
    mass_loss: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """(v_max (n,) m/s, dv_max/dz (n,) 1/s) at altitudes (n,) and masses (n,): the limit of
    `max_descent_speed_for` and its slope in altitude (0 at or below the pad): a / v_max at the
    mass now, a central difference over +-1 cm with the mass loss."""
    z = np.asarray(altitude_m, dtype=float)
    m = np.broadcast_to(np.asarray(mass_kg, dtype=float), z.shape)
    if not mass_loss:
        a = np.maximum(braking_force_n / m - gravity_mps2, 0.0)
        v = np.sqrt(land_speed_mps**2 + 2.0 * a * np.maximum(z, 0.0))
        return v, np.where(z > 0.0, a / v, 0.0)
    args = (braking_force_n, land_speed_mps, gravity_mps2)

    def limit(zs: np.ndarray) -> np.ndarray:
        pairs = zip(zs.tolist(), m.tolist(), strict=True)
        return np.array([max_descent_speed_mass_loss_mps(zi, mi, *args) for zi, mi in pairs])

    h = 0.01
    lo = np.maximum(z - h, 0.0)
    slope = (limit(z + h) - limit(lo)) / (z + h - lo)
    return limit(z), np.where(z > 0.0, slope, 0.0)


@jitable
def brake_fires(
    altitude_m: float,
    vertical_speed_mps: float,
    mass_kg: float,
    counted_force_n: float,
    braking_force_n: float,
    land_speed_mps: float,
    touchdown_speed_mps: float,
    gravity_mps2: float,
    dt_s: float,
    mass_loss: bool,
) -> int:
    """The limit a command fires (NO_LIMIT where none): the command's vertical force counted on
    (counted_force_n, N) for one step of dt_s from (altitude, vertical speed (up +), mass), then
    the descent speed against the braking limit of braking_force_n at the altitude reached
    (DESCENT, or DESCENT_MASS_LOSS where mass_loss); a step that ends on the ground
    (touchdown_speed_mps > 0) is judged by its touchdown speed instead (TOUCHDOWN). Braking at
    the margin once the limit is crossed merely keeps the excess speed: hence one step ahead."""
    a_z = counted_force_n / mass_kg - gravity_mps2
    vz = vertical_speed_mps + a_z * dt_s
    z = altitude_m + (vertical_speed_mps + 0.5 * a_z * dt_s) * dt_s
    if touchdown_speed_mps <= 0.0 or z > 0.0:
        limit = max_descent_speed_for(
            z, mass_kg, braking_force_n, land_speed_mps, gravity_mps2, mass_loss
        )
        if -vz > limit:
            return DESCENT_MASS_LOSS if mass_loss else DESCENT
        return NO_LIMIT
    if vertical_speed_mps**2 - 2.0 * a_z * max(altitude_m, 0.0) > touchdown_speed_mps**2:
        return TOUCHDOWN
    return NO_LIMIT


__all__ = [
    "DESCENT",
    "DESCENT_MASS_LOSS",
    "EXHAUST_VELOCITY_MPS",
    "NO_LIMIT",
    "TOUCHDOWN",
    "brake_fires",
    "descent_limits",
    "max_descent_speed_for",
    "max_descent_speed_mass_loss_mps",
    "max_descent_speed_mps",
]
