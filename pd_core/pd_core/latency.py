"""Actuation-latency compensation: a Smith predictor with the delay identified in flight (ours).

A command that acts d steps late is decided on a state d steps old. The quantised vertical loop
then rings (one step of free fall is 0.74 m/s) and touches down too fast: with two steps of
delay (400 ms) the shipped policy lands 78.4 % and ZEM/ZEV behind the shield 69.4 % (stress
`delay2`, seed 30000000, 500 episodes). Acting on the state the command will meet instead
(the observed state carried through the d commands still in the pipeline, on the nominal
dynamics: these are known, the controller issued them) lands 100 % for both with the delay
told; the policy needs no retraining, since it then flies as if there were none.

The delay is not told: it is identified from the lander's own response. Each step, the change
of the observed velocity is compared with what each candidate lag d = 0..max of the issued
commands would have produced, and the squared residuals are summed with a forgetting factor;
the smallest sum wins (ties go to the shorter lag, so a lander whose commands never changed is
not predicted at all). A level change of the vertical thrust moves the velocity by 0.65 m/s in
a step and a lateral one by 0.33 m/s, several times the velocity noise of a Doppler
velocimeter, so the right lag stands out after a few changes of command; a thrust error,
misalignment or gust shifts every candidate alike and does not bias the choice.

The plant is identified too. Each lag keeps a thrust matrix (delivered force = matrix @
command), estimated by a Kalman filter from the same measurements (the force m dv / dt - m g
against the command that lag says was flown), with a measurement noise taken from the lag's own
residuals, so metre-class navigation noise weighs each step less. The prediction through the
pipeline uses the chosen lag's matrix. With a 10 % thrust error and 4 deg of misalignment on top
of two steps of delay, predicting on the nominal plant left the shipped policy at 98.0 % (seed
60000000; 98.4 % at 70000000) and the identified plant 100.0 % (99.8 %); with 3 m / 0.3 m/s of
navigation noise, 99.0 % against 99.2 % (98.4 % against 98.6 %); 500 episodes each.

The braking shield counts on the vertical entry of that matrix where it shows the engine short
(`vertical_thrust_scale`: the estimate plus three standard deviations). Under metre-class
navigation noise the per-step estimate sharpens slowly: the noise enters every step's velocity
change, and consecutive errors cancel, but the filter counts them as independent. So the
vertical gain is also measured over 1 s windows (the whole velocity change against the
commanded one, the lateral commands' identified upward part removed), where the noise enters
once; the shield takes the lower of the two bounds. With 12 % thrust errors and 3 m / 0.3 m/s
of noise, the shipped policy landed 95.2 % on the per-step bound alone and 98.2 % with both
(`data/shortfall.yaml`, 500 episodes, seed 99000000).

Where the navigation is noisy the prediction starts from the navigation filter's estimate
(`pd_core.navfilter`, fed with the command this lag and matrix say the plant flew) instead of the
observed state; the lag is still identified on the observed velocities.

One lander per row: `LatencyCompensator` keeps the commands issued and the scores of each row;
`CompensatesLatency` puts it in front of a policy or a shielded controller, as the shield
settings ask (`ShieldParams.max_delay_steps`): `pd_core.evaluate.fly_episodes` tells it which
rows are flying, the policy node flies row 0.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pd_core.actions import ActionSpace
from pd_core.config import DT_S, GRAVITY_MPS2
from pd_core.dynamics import step
from pd_core.navfilter import WARM_STEPS as NAV_WARM_STEPS
from pd_core.navfilter import NavFilter
from pd_core.rowmemory import RowMemory

FORGET_PER_STEP = 0.97
"""weight of a residual one step older (a memory of about 30 steps, 6 s: long against the
velocity noise, short against a change of the delay in flight)"""
SWITCH_MARGIN_MPS2 = 0.3
"""(m/s)^2 by which another lag's score must beat the current one's for the estimate to move:
about one vertical level change (0.42) or three lateral ones (0.11 each) of net evidence. Without
it, 0.1 m/s of velocity noise made 0.4 % of the steps of flights without delay predict with a
spurious lag early in the flight (0 % with it; 300 episodes, seed 9400000)"""
TIE_BREAK_MPS2 = 1e-3
"""(m/s)^2 added per step of lag to the initial score: equal evidence chooses the shorter lag"""
THRUST_MATRIX_PRIOR_SD = 0.1
"""prior spread of each entry of the thrust matrix (delivered = matrix @ command): 10 % covers
the thrust errors (5-10 %) and misalignments (2-4 deg, 0.03-0.07) a flight team flies"""
FORCE_NOISE_N = 1000.0
"""prior spread of one step's measured force per axis, m dv / dt (0.1 m/s of velocity noise on a
2 t lander gives 1400 N; 100 N of disturbance without it); then the lander's own residuals
decide it (`LatencyCompensator.force_noise_var`)"""
SHORTFALL_SD = 3.0
"""standard deviations of its estimate added to the identified vertical gain before the braking
shield counts on it (`vertical_thrust_scale`): a shortfall it acts on is one the measurements
show, not the estimate's noise on an engine that delivers what it should"""
WINDOW_STEPS = 5
"""steps (1 s) over which the vertical gain is also measured from the whole velocity change:
navigation noise enters a window's change once, however long the window, where the per-step
filter sees it in every step's change (consecutive errors cancel, but it counts them as
independent), so under metre-class noise the window measure is the sharper one"""
WINDOW_FORGET = 0.9
"""weight of a window one window older (a memory of about 10 s)"""
WINDOW_NOISE_MPS = 0.5
"""prior spread of one window's velocity-change residual (worth two windows): 0.3 m/s of velocity
noise twice, plus gusts"""
WINDOW_MIN_EVIDENCE = 25.0
"""(m/s)^2 of commanded vertical velocity change (summed squares over windows) below which the
window measure is not used: about one second of full vertical thrust"""
JUMP_M = 50.0
"""a row whose observed position is this far from where its last observation was heading
starts a new episode (a reset of the simulator): its memory is cleared"""


_COV0 = np.eye(3) * THRUST_MATRIX_PRIOR_SD**2


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
    sxx: np.ndarray, sxy: np.ndarray, syy: np.ndarray, n: np.ndarray, n_sd: float
) -> np.ndarray:
    """Upper bound (estimate + n_sd standard deviations) of the vertical gain from the windows'
    forgetting sums: sxx of the commanded velocity change squared, sxy of it times the observed
    one, syy of the squared residuals, n of the windows ((m/s)^2, (m/s)^2, (m/s)^2, count);
    infinite where there is less evidence than WINDOW_MIN_EVIDENCE."""
    enough = sxx >= WINDOW_MIN_EVIDENCE
    safe = np.where(enough, sxx, 1.0)
    noise_var = (syy + 2.0 * WINDOW_NOISE_MPS**2) / (n + 2.0)
    bound = sxy / safe + n_sd * np.sqrt(noise_var / safe)
    return np.where(enough, bound, np.inf)


class LatencyCompensator(RowMemory):
    """Per-row memory of the commands issued and the lag scores; see the module docstring."""

    def __init__(
        self,
        max_delay_steps: int,
        n_rows: int = 1,
        forget: float = FORGET_PER_STEP,
        margin: float = SWITCH_MARGIN_MPS2,
        thrust_model: bool = True,
        nav_filter: bool = False,
    ):
        if not 0 <= max_delay_steps <= 10:
            raise ValueError(f"max_delay_steps must be in [0, 10], got {max_delay_steps}")
        self.max_delay_steps = int(max_delay_steps)
        self.forget = forget
        self.margin = margin
        self.thrust_model = thrust_model
        """identify the thrust matrix of each lag too (else the nominal plant: identity)"""
        self.nav = NavFilter(n_rows) if nav_filter else None
        """the navigation filter the prediction starts from (None: the observed state)"""
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
            "_score": np.tile(TIE_BREAK_MPS2 * np.arange(lags, dtype=float), (n_rows, 1)),
            # the lag each row is predicted with (its current estimate)
            "delay_steps": np.zeros(n_rows, dtype=np.int64),
            # thrust matrix of each row and lag (delivered force = gain @ command)
            "gain": np.tile(np.eye(3), (n_rows, lags, 1, 1)),
            "_cov": np.tile(_COV0, (n_rows, lags, 1, 1)),
            # running mean square of each lag's force residual per axis (N^2)
            "force_noise_var": np.full((n_rows, lags), FORCE_NOISE_N**2),
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
        jumped = seen & (np.linalg.norm(obs[:, 0:3] - heading, axis=1) > JUMP_M)
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

    def vertical_thrust_scale(self, rows: np.ndarray, n_sd: float = SHORTFALL_SD) -> np.ndarray:
        """(B,) delivered over commanded vertical thrust of rows (B,) as far as the evidence
        shows it short: their lag's identified vertical gain (the thrust error and the
        misalignment's cosine together) plus `n_sd` of its standard deviation, so an engine
        that delivers what it should reads >= 1 (1 where nothing is identified)."""
        rows = np.asarray(rows, dtype=np.int64)
        self.grow(int(rows.max()) + 1 if len(rows) else 0)
        if self.max_delay_steps == 0 or not self.thrust_model:
            return np.ones(len(rows))
        _, gain, sd = self._vertical_gain(rows)
        sums = self._win_sums[rows]
        return np.minimum(gain + n_sd * sd, window_gain_bound(*sums.T, n_sd))

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
            else self.nav.engaged[rows] | (self.nav.steps(rows) < NAV_WARM_STEPS)
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
        done = r[self._win_steps[r] >= WINDOW_STEPS]
        if not len(done):
            return
        x, y = self._win[done].T
        sums = WINDOW_FORGET * self._win_sums[done]
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


class CompensatesLatency:
    """Mixin for actors with `act_batch` and `actions`: `act_rows` (landers flown row by row,
    `pd_core.evaluate.fly_episodes`) and `act_online` (one lander, row 0: the policy node) decide
    on the states the commands will meet when `self.latency` is set; `act` and `act_batch` stay
    stateless (labels, demonstrations, training)."""

    latency: LatencyCompensator | None = None
    _online_episode: int | None = None
    actions: ActionSpace
    act_batch: Any  # the actor's own: physical states (B, 7) -> actions (B,)

    def begin_episodes(self, n: int) -> None:
        """Rows 0..n-1 start new episodes."""
        if self.latency is not None:
            self.latency.reset(n)

    def act_rows(self, states: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Actions (B,) for the observed states (B, 7) of rows (B,)."""
        if self.latency is None:
            return self.act_batch(states)
        predicted = self.latency.predict(states, rows)
        scale = self.latency.vertical_thrust_scale(rows)
        actions = np.asarray(self.act_batch(predicted, vertical_thrust_scale=scale), dtype=np.int64)
        self.latency.record(rows, self.actions.table_n[actions])
        return actions

    def act_online(self, state: np.ndarray, episode: int | None = None) -> int:
        """Action for the next observed state (7,) of the one lander flown (row 0); a new
        `episode` number (the simulator's) restarts the memory."""
        if episode is not None and episode != self._online_episode:
            self._online_episode = episode
            self.begin_episodes(1)
        s = np.asarray(state, dtype=float).reshape(1, 7)
        return int(self.act_rows(s, np.zeros(1, dtype=np.int64))[0])
