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
once per window instead of every step). Until the engine has been measured (the gain's standard
deviation below `measured_gain_sd`), the rules may count on no more than `unmeasured_thrust`
(1 by default: nominal; 0.8 counts on the weakest engine promised, issue 68).

Where the navigation is noisy the prediction starts from the navigation filter's estimate
(`pd_core.runtime.navfilter`, fed with the command this lag and matrix say the plant flew).
Settings: `pd_core.runtime.config.LatencyConfig`; one lander per row (`RowMemory`). The arithmetic,
row by row, is compiled: `pd_core.runtime.kernels_latency` (`predict_rows`, `_observe_row`, on a
`LatencyMemory` and `LatencySettings`).
"""

from __future__ import annotations

import numpy as np

from pd_core.runtime.config import LatencyConfig, NavFilterConfig
from pd_core.runtime.kernels import consts
from pd_core.runtime.kernels_latency import (
    lag_residuals_rows,
    record_rows,
    thrust_scale_rows,
    window_bounds,
)
from pd_core.runtime.kernels_state import LatencyMemory, LatencySettings, NavMemory, Pipeline
from pd_core.runtime.kernels_step import INVALID, JUMPED, before_actor
from pd_core.runtime.navfilter import NavFilter
from pd_core.runtime.rowmemory import RowMemory
from pd_core.state import STATE_LIMITS, as_state_rows, check_state

_CONSTS = consts()
_IDENTITY = np.eye(3)[None, None]


def lag_residuals(
    dv_mps: np.ndarray,
    mass_kg: np.ndarray,
    issued_n: np.ndarray,
    gain: np.ndarray | None = None,
) -> np.ndarray:
    """(B, L) squared norm of the observed velocity change (B, 3) over the last step minus the one
    each lag would give: lag d applies `issued_n[:, d]` (B, L, 3), the command issued d + 1
    steps before now, through the thrust matrix `gain[:, d]` (B, L, 3, 3; None: identity), on
    landers of mass (B,) kg (`pd_core.runtime.kernels_latency.lag_residual`)."""
    issued = np.ascontiguousarray(issued_n, dtype=float)
    g = _IDENTITY if gain is None else np.ascontiguousarray(gain, dtype=float)
    return lag_residuals_rows(
        np.ascontiguousarray(dv_mps, dtype=float),
        np.ascontiguousarray(mass_kg, dtype=float),
        issued,
        g,
        gain is not None,
        _CONSTS,
    )


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
    infinite where there is less evidence than `cfg.window_min_evidence`. The noise variance of
    a window is (syy + 2 window_noise^2) / (n + 2)
    (`pd_core.runtime.kernels_latency.window_bound`)."""
    sums = [np.ascontiguousarray(v, dtype=float).reshape(-1) for v in (sxx, sxy, syy, n)]
    return window_bounds(*sums, float(n_sd), *_window_settings(cfg))


def _window_settings(cfg: LatencyConfig) -> tuple[float, float]:
    """(minimum evidence, 2 window_noise^2): the window bound's settings, as kernels take them."""
    return float(cfg.window_min_evidence), 2.0 * cfg.window_noise_mps**2


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
        params = np.array(
            [
                cfg.max_delay_steps, cfg.thrust_model, cfg.forget_per_step,
                cfg.switch_margin_mps2, cfg.jump_m, cfg.window_steps, cfg.window_forget,
            ],
            dtype=float,
        )  # fmt: skip
        min_evidence, noise2 = _window_settings(cfg)
        self.settings = LatencySettings(
            params=params,
            nav=self.nav is not None,
            measures_thrust=bool(cfg.max_delay_steps > 0 and cfg.thrust_model),
            shortfall_sd=float(cfg.shortfall_sd),
            window_min_evidence=min_evidence,
            window_noise2=noise2,
            unmeasured_thrust=float(cfg.unmeasured_thrust),
            measured_gain_sd=float(cfg.measured_gain_sd),
            dynamics=_CONSTS,
        )
        """the settings the kernels take (`LatencySettings`)"""
        self._nav_kernels = NavFilter(nav, 0) if self.nav is None else self.nav
        """the filter whose memory and model the kernels are given (one of no rows where there
        is no filter)"""
        self.reset(n_rows)

    def reset(self, n_rows: int) -> None:
        """Forget everything: n_rows landers whose engines are not lit yet."""
        super().reset(n_rows)
        if self.nav is not None:
            self.nav.reset(n_rows)
        self._memory: tuple[LatencyMemory, NavMemory] | None = None
        self._plain: tuple[tuple[tuple, ...], tuple] | None = None

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
        if n_rows <= self.n_rows:
            return
        super().grow(n_rows)
        if self.nav is not None:
            self.nav.grow(n_rows)
        self._memory = None
        self._plain = None

    def _kernel_memory(self) -> tuple[LatencyMemory, NavMemory]:
        """The memory the kernels take: this compensator's and its navigation filter's (the
        arrays themselves; built again only after `reset` or `grow` replace them, `clear`
        writes into them)."""
        if self._memory is None:
            memory = LatencyMemory(
                issued=self._issued, last=self._last, score=self._score, delay=self.delay_steps,
                gain=self.gain, cov=self._cov, force_var=self.force_noise_var, win=self._win,
                win_steps=self._win_steps, win_sums=self._win_sums,
            )  # fmt: skip
            self._memory = (memory, self._nav_kernels.memory())
        return self._memory

    def _plain_groups(self) -> tuple[tuple[tuple, ...], tuple]:
        """(`before_actor`'s memory, settings, navigation memory and model; `after_actor`'s
        `Pipeline`), each a plain tuple of its named tuple's fields: what the two kernels of
        every decision are handed (`pd_core.runtime.kernels_step`: cheaper to dispatch than the
        named tuples). Kept as `_kernel_memory`."""
        if self._plain is None:
            memory, nav = self._kernel_memory()
            pipeline = Pipeline(
                recorded=True, issued=self._issued, delay=self.delay_steps, engaged=nav.engaged,
                nav=self.settings.nav,
            )  # fmt: skip
            groups = (memory, self.settings, nav, self._nav_kernels.model)
            self._plain = (tuple(tuple(g) for g in groups), tuple(pipeline))
        return self._plain

    def clear(self, rows: np.ndarray) -> None:
        super().clear(rows)
        if self.nav is not None:
            self.nav.clear(rows)

    def predict(self, observed: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """States (B, 7) the next commands of rows (B,) will meet, given their observed states
        (B, 7); updates each row's lag estimate with the velocity change it just saw. A row
        observed more than `jump_m` from where it was heading starts a new episode (cleared).
        ValueError (`check_state`'s) where an observed state is invalid."""
        return self.predict_scaled(observed, rows)[0]

    def predict_scaled(
        self, observed: np.ndarray, rows: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(`predict`, then `vertical_thrust_scale`) of rows (B,) in one compiled call
        (`kernels_step.before_actor`), the observed states validated first."""
        rows = np.asarray(rows, dtype=np.int64)
        obs = as_state_rows(observed)
        top = int(rows.max()) + 1 if len(rows) else 0
        if top > self.n_rows:
            self.grow(top)
        if self.max_delay_steps == 0 and self.nav is None:
            check_state(obs)
            self._last[rows] = obs
            return obs, np.ones(len(rows))
        out = np.empty_like(obs)
        scale = np.empty(len(rows))
        jumped = np.empty(len(rows), dtype=bool)
        groups = self._plain_groups()[0]
        while True:
            code = before_actor(obs, STATE_LIMITS, rows, out, jumped, scale, *groups)
            if code == INVALID:
                check_state(observed)
            if code != JUMPED:
                return out, scale
            self.clear(rows[jumped])

    def pipeline(self) -> tuple:
        """The `Pipeline` fields as a plain tuple (as `kernels_step.after_actor` is handed
        them): the issued commands, the lag each row flies and the navigation filter engaged,
        the arrays `after_actor` records into and reads (the memory, not copies)."""
        return self._plain_groups()[1]

    def vertical_thrust_scale(self, rows: np.ndarray, n_sd: float | None = None) -> np.ndarray:
        """(B,) delivered over commanded vertical thrust of rows (B,) as far as the evidence
        shows it short: their lag's identified vertical gain (the thrust error and the
        misalignment's cosine together) plus `n_sd` of its standard deviation, so an engine
        that delivers what it should reads >= 1 (1 where nothing is identified), or the window
        bound (`window_gain_bound`) where lower; at most `unmeasured_thrust` until that gain's
        standard deviation is below `measured_gain_sd` (the engine not yet measured)."""
        rows = np.asarray(rows, dtype=np.int64)
        self.grow(int(rows.max()) + 1 if len(rows) else 0)
        if self.max_delay_steps == 0 or not self.thrust_model:
            return np.ones(len(rows))
        n_sd = self.cfg.shortfall_sd if n_sd is None else n_sd
        return thrust_scale_rows(rows, self._kernel_memory()[0], self.settings, float(n_sd))

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

    def record(self, rows: np.ndarray, thrust_n: np.ndarray) -> None:
        """The commands (B, 3), N, just issued for rows (B,)."""
        rows = np.asarray(rows, dtype=np.int64)
        thrust = np.ascontiguousarray(thrust_n, dtype=float).reshape(-1, 3)
        record_rows(self._issued, rows, thrust)
