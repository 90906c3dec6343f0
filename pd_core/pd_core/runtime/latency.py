"""Actuation-latency compensation: a Smith predictor with the delay identified in flight (ours).

A command that acts d steps late is decided on a state d steps old. Acting instead on the state
the command will meet (the observed state carried through the d commands still in the pipeline,
on the nominal dynamics: the controller issued them) lets a policy fly as if there were no delay.

The delay is not told: it is identified from the lander's own response. Each step, the change of
the observed velocity is compared with what each candidate lag d = 0..max of the issued commands
would have produced, and the squared residuals are summed with a forgetting factor; the smallest
sum wins, by a switch margin (ties go to the shorter lag).

The plant is identified too. Each lag keeps a thrust matrix (delivered force = matrix @ command),
estimated by a Kalman filter from the same measurements, with a measurement noise taken from the
lag's own residuals. The prediction through the pipeline uses the chosen lag's matrix. The rules
count on the vertical entry of that matrix where it shows the engine short
(`vertical_thrust_scale`: the estimate plus `shortfall_sd` standard deviations, and the lower of
that and the same gain measured over windows of `window_steps`, where navigation noise enters
once per window instead of every step).

Where the navigation is noisy the prediction starts from the navigation filter's estimate
(`pd_core.runtime.navfilter`, fed with the command this lag and matrix say the plant flew).
Settings: `pd_core.runtime.config.LatencyConfig`; one lander per row (`RowMemory`).
"""

from __future__ import annotations

import numpy as np

from pd_core.config import DT_S, GRAVITY_MPS2
from pd_core.dynamics import step
from pd_core.runtime.config import LatencyConfig, NavFilterConfig
from pd_core.runtime.navfilter import NavFilter
from pd_core.runtime.rowmemory import RowMemory


def propagate(states: np.ndarray, queued_thrust_n: np.ndarray, dt_s: float = DT_S) -> np.ndarray:
    """States (B, 7) carried through the commands (B, d, 3), N, oldest first, on the nominal
    dynamics without disturbance: where a command issued now will find the lander."""
    s = np.array(states, dtype=float)
    zero = np.zeros((len(s), 3))
    for k in range(queued_thrust_n.shape[1]):
        s = step(s, queued_thrust_n[:, k], zero, dt_s)
    return s


def lag_residuals(
    dv_mps: np.ndarray,
    mass_kg: np.ndarray,
    issued_n: np.ndarray,
    gain: np.ndarray | None = None,
    dt_s: float = DT_S,
) -> np.ndarray:
    """(B, L) squared norm of the observed velocity change (B, 3) over the last step minus the one
    each lag would give: lag d applies `issued_n[:, d]` (B, L, 3), the command issued d + 1
    steps before now, through the thrust matrix `gain[:, d]` (B, L, 3, 3; None: identity), on
    landers of mass (B,) kg."""
    delivered = issued_n if gain is None else np.einsum("blij,blj->bli", gain, issued_n)
    expected = (delivered / mass_kg[:, None, None] + GRAVITY_MPS2) * dt_s
    return ((dv_mps[:, None, :] - expected) ** 2).sum(axis=-1)


def update_thrust_matrix(
    gain: np.ndarray,
    cov: np.ndarray,
    command_n: np.ndarray,
    force_n: np.ndarray,
    noise_var_n2: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """One Kalman step of delivered force = gain @ command (per row and lag; each output axis an
    independent measurement with the same regressor): gain (..., 3, 3), the covariance of each
    of its rows cov (..., 3, 3), the command (..., 3), the force measured over the step (..., 3)
    and its noise variance (...), N^2. A zero command carries no information."""
    pu = np.einsum("...ij,...j->...i", cov, command_n)
    k = pu / (noise_var_n2 + np.einsum("...i,...i->...", command_n, pu))[..., None]
    err = force_n - np.einsum("...ij,...j->...i", gain, command_n)
    return gain + err[..., :, None] * k[..., None, :], cov - k[..., :, None] * pu[..., None, :]


def window_gain_bound(
    sxx: np.ndarray,
    sxy: np.ndarray,
    syy: np.ndarray,
    n: np.ndarray,
    n_sd: float,
    cfg: LatencyConfig,
) -> np.ndarray:
    """Upper bound (estimate + n_sd standard deviations) of the vertical gain from the windows'
    forgetting sums: sxx of the commanded velocity change squared, sxy of it times the observed
    one, syy of the squared residuals, n of the windows ((m/s)^2, (m/s)^2, (m/s)^2, count);
    infinite where there is less evidence than `cfg.window_min_evidence`."""
    enough = sxx >= cfg.window_min_evidence
    safe = np.where(enough, sxx, 1.0)
    noise_var = (syy + 2.0 * cfg.window_noise_mps**2) / (n + 2.0)
    bound = sxy / safe + n_sd * np.sqrt(noise_var / safe)
    return np.where(enough, bound, np.inf)


class LatencyCompensator(RowMemory):
    """Per-row memory of the commands issued and the lag scores; see the module docstring."""

    def __init__(self, cfg: LatencyConfig, nav: NavFilterConfig, n_rows: int = 1) -> None:
        self.cfg = cfg
        self.max_delay_steps = cfg.max_delay_steps
        self.forget = cfg.forget_per_step
        self.margin = cfg.switch_margin_mps2
        self.thrust_model = cfg.thrust_model
        """identify the thrust matrix of each lag too (else the nominal plant: identity)"""
        self.nav = NavFilter(nav, n_rows) if nav.enabled else None
        """the navigation filter the prediction starts from (None: the observed state)"""
        self._cov0 = np.eye(3) * cfg.thrust_matrix_prior_sd**2
        self.reset(n_rows)

    def reset(self, n_rows: int) -> None:
        """Forget everything: n_rows landers whose engines are not lit yet."""
        super().reset(n_rows)
        if self.nav is not None:
            self.nav.reset(n_rows)

    def _fresh(self, n_rows: int) -> dict[str, np.ndarray]:
        """The memory of n_rows landers that have flown nothing yet."""
        lags = self.max_delay_steps + 1
        return {
            "_issued": np.zeros((n_rows, lags, 3)),  # [:, k]: issued k + 1 steps ago
            "_last": np.full((n_rows, 7), np.nan),  # last observed state (nan: none yet)
            "_score": np.tile(self.cfg.tie_break_mps2 * np.arange(lags, dtype=float), (n_rows, 1)),
            # the lag each row is predicted with (its current estimate)
            "delay_steps": np.zeros(n_rows, dtype=np.int64),
            # thrust matrix of each row and lag (delivered force = gain @ command)
            "gain": np.tile(np.eye(3), (n_rows, lags, 1, 1)),
            "_cov": np.tile(self._cov0, (n_rows, lags, 1, 1)),
            # running mean square of each lag's force residual per axis (N^2)
            "force_noise_var": np.full((n_rows, lags), self.cfg.force_noise_n**2),
            # the window in progress: commanded and observed vertical velocity change (m/s)
            "_win": np.zeros((n_rows, 2)),
            "_win_steps": np.zeros(n_rows, dtype=np.int64),
            # forgetting sums over finished windows: sxx, sxy, syy (residual^2), count
            "_win_sums": np.zeros((n_rows, 4)),
        }

    def grow(self, n_rows: int) -> None:
        super().grow(n_rows)
        if self.nav is not None:
            self.nav.grow(n_rows)

    def clear(self, rows: np.ndarray) -> None:
        super().clear(rows)
        if self.nav is not None:
            self.nav.clear(rows)

    def predict(self, observed: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """States (B, 7) the next commands of rows (B,) will meet, given their observed states
        (B, 7); updates each row's lag estimate with the velocity change it just saw."""
        rows = np.asarray(rows, dtype=np.int64)
        obs = np.asarray(observed, dtype=float).reshape(-1, 7)
        self.grow(int(rows.max()) + 1 if len(rows) else 0)
        if self.max_delay_steps == 0 and self.nav is None:
            self._last[rows] = obs
            return obs
        last = self._last[rows]
        seen = ~np.isnan(last[:, 0])
        heading = last[:, 0:3] + last[:, 3:6] * DT_S
        jumped = seen & (np.linalg.norm(obs[:, 0:3] - heading, axis=1) > self.cfg.jump_m)
        if jumped.any():
            self.clear(rows[jumped])
            seen &= ~jumped
        if seen.any() and self.max_delay_steps > 0:
            self._observe(rows[seen], obs[seen, 3:6] - last[seen, 3:6], last[seen, 6])
        self._last[rows] = obs
        out = (
            obs.copy()
            if self.nav is None
            else self.nav.estimate(obs, rows, self.applied(rows, obs))
        )
        start = out.copy()
        for d in range(1, self.max_delay_steps + 1):
            sel = self.delay_steps[rows] == d
            if sel.any():
                queued = self._issued[rows[sel], :d][:, ::-1]  # oldest first
                if self.thrust_model:
                    g = self.gain[rows[sel], d][:, None]
                    queued = np.einsum("bkij,bkj->bki", g, queued)
                out[sel] = propagate(start[sel], queued)
        return out

    def vertical_thrust_scale(self, rows: np.ndarray, n_sd: float | None = None) -> np.ndarray:
        """(B,) delivered over commanded vertical thrust of rows (B,) as far as the evidence
        shows it short: their lag's identified vertical gain (the thrust error and the
        misalignment's cosine together) plus `n_sd` of its standard deviation, so an engine
        that delivers what it should reads >= 1 (1 where nothing is identified)."""
        rows = np.asarray(rows, dtype=np.int64)
        self.grow(int(rows.max()) + 1 if len(rows) else 0)
        if self.max_delay_steps == 0 or not self.thrust_model:
            return np.ones(len(rows))
        n_sd = self.cfg.shortfall_sd if n_sd is None else n_sd
        _, gain, sd = self._vertical_gain(rows)
        sums = self._win_sums[rows]
        return np.minimum(gain + n_sd * sd, window_gain_bound(*sums.T, n_sd, self.cfg))

    def _vertical_gain(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(lag, identified vertical gain, its standard deviation), each (B,), of rows (B,)."""
        lag = self.delay_steps[rows]
        sd = np.sqrt(np.maximum(self._cov[rows, lag, 2, 2], 0.0))
        return lag, self.gain[rows, lag, 2, 2], sd

    def evidence(self, rows: np.ndarray) -> dict[str, np.ndarray]:
        """What the memory of rows (B,) has measured, each (B,): the lag flown (`delay_steps`),
        its identified vertical gain and that gain's standard deviation (`gain`, `gain_sd`), the
        r.m.s. force residual per axis (`force_sd_n`, N: gusts and what the model lacks), and
        whether the navigation filter has found noise or is still warming up (`nav_noisy`)."""
        rows = np.asarray(rows, dtype=np.int64)
        self.grow(int(rows.max()) + 1 if len(rows) else 0)
        lag, gain, sd = self._vertical_gain(rows)
        nav = (
            np.zeros(len(rows), dtype=bool)
            if self.nav is None
            else self.nav.engaged[rows] | (self.nav.steps(rows) < self.nav.cfg.warm_steps)
        )
        return {
            "delay_steps": lag,
            "gain": gain,
            "gain_sd": sd,
            "force_sd_n": np.sqrt(self.force_noise_var[rows, lag]),
            "nav_noisy": nav,
        }

    def describe(self, row: int = 0) -> str:
        """One phrase on what row's memory decided (the policy node's statistics line)."""
        self.grow(row + 1)
        out = f"actuation delay {self.delay_steps[row]} step(s)"
        short = float(self.vertical_thrust_scale(np.array([row]))[0])
        if short < 1.0:
            out += f", vertical thrust {100.0 * short:.0f} % of nominal"
        if self.nav is None:
            return out
        if not self.nav.engaged[row]:
            return out + ", navigation filter standing by"
        sd = np.sqrt(self.nav.noise_var[row])
        return out + f", navigation filter on (noise {sd[0]:.1f} m, {sd[1]:.2f} m/s)"

    def applied(self, rows: np.ndarray, states: np.ndarray) -> np.ndarray:
        """Acceleration (B, 3), m/s^2, that the command each row's lag says the plant flew over
        the last step gives landers in states (B, 7) (its thrust matrix applied)."""
        lag = self.delay_steps[rows]
        cmd = self._issued[rows, lag]
        if self.thrust_model:
            cmd = np.einsum("bij,bj->bi", self.gain[rows, lag], cmd)
        return cmd / states[:, 6:7] + GRAVITY_MPS2

    def _observe(self, r: np.ndarray, dv_mps: np.ndarray, mass_kg: np.ndarray) -> None:
        """Rows r saw the velocity change dv (B, 3) over the last step, at mass (B,): score the
        lags, identify their thrust matrices, move the lag estimate where the evidence says."""
        gain = self.gain[r] if self.thrust_model else None
        res = lag_residuals(dv_mps, mass_kg, self._issued[r], gain)
        if self.thrust_model:
            m = mass_kg[:, None]
            force = m * (dv_mps / DT_S - GRAVITY_MPS2)
            var = (
                self.forget * self.force_noise_var[r]
                + (1.0 - self.forget) * res * (m / DT_S) ** 2 / 3.0
            )
            self.force_noise_var[r] = var
            self.gain[r], self._cov[r] = update_thrust_matrix(
                self.gain[r], self._cov[r], self._issued[r], force[:, None, :], var
            )
        score = self.forget * self._score[r] + res
        self._score[r] = score
        best = np.argmin(score, axis=1)
        now = self.delay_steps[r]
        k = np.arange(len(r))
        switch = score[k, best] < score[k, now] - self.margin
        self.delay_steps[r] = np.where(switch, best, now)
        if self.thrust_model:
            self._observe_window(r, dv_mps[:, 2], mass_kg)

    def _observe_window(self, r: np.ndarray, dvz_mps: np.ndarray, mass_kg: np.ndarray) -> None:
        """Add the last step to rows r's window: the vertical velocity change the lag's vertical
        command gives at nominal thrust, and the one observed less gravity and less what its
        lateral commands give upwards through the identified matrix (misalignment); a full
        window goes into the forgetting sums (`window_gain_bound`)."""
        lag = self.delay_steps[r]
        cmd = self._issued[r, lag]
        sideways = np.einsum("bj,bj->b", self.gain[r, lag, 2, 0:2], cmd[:, 0:2])
        commanded = cmd[:, 2] / mass_kg * DT_S
        observed = dvz_mps - (GRAVITY_MPS2[2] + sideways / mass_kg) * DT_S
        self._win[r] += np.stack([commanded, observed], axis=1)
        self._win_steps[r] += 1
        done = r[self._win_steps[r] >= self.cfg.window_steps]
        if not len(done):
            return
        x, y = self._win[done].T
        sums = self.cfg.window_forget * self._win_sums[done]
        sums[:, 0] += x * x
        sums[:, 1] += x * y
        gain = np.where(sums[:, 0] > 0.0, sums[:, 1] / np.maximum(sums[:, 0], 1e-12), 1.0)
        sums[:, 2] += (y - gain * x) ** 2
        sums[:, 3] += 1.0
        self._win_sums[done] = sums
        self._win[done] = 0.0
        self._win_steps[done] = 0

    def record(self, rows: np.ndarray, thrust_n: np.ndarray) -> None:
        """The commands (B, 3), N, just issued for rows (B,)."""
        rows = np.asarray(rows, dtype=np.int64)
        self._issued[rows] = np.concatenate(
            [np.asarray(thrust_n, dtype=float)[:, None], self._issued[rows, :-1]], axis=1
        )
