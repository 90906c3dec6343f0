"""The paper's solver (Sec. 3.1): SciPy SLSQP over the 3 n_control + 1 variables.

Either with SciPy's default finite-difference gradients (`exact_gradients=False`, as the paper
ran it) or with the exact gradients of `Problem.gradients`.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from scipy.optimize import minimize

from pd_core.ocp.guess import initial_guess
from pd_core.ocp.model import TF_MAX_S, TF_MIN_S, Problem, SolverOutput, SolveTimeout

_T_SCALE_N = 1e4  # decision variables in units of 10 kN and 10 s keep SLSQP well conditioned
_TF_SCALE_S = 10.0
_C_SCALE = np.array([100.0, 100.0, 100.0, 10.0, 10.0, 10.0])  # m, m/s


class _Evaluator:
    """Objective, constraints and their gradients at y, computed once per y (SciPy asks each
    of them separately at the same point)."""

    def __init__(self, pb: Problem, exact: bool, j_scale: float, deadline: float) -> None:
        self.pb, self.exact, self.j_scale, self.deadline = pb, exact, j_scale, deadline
        self.key: bytes | None = None
        self.vals: dict[str, Any] = {}

    def unpack(self, y: np.ndarray) -> tuple[np.ndarray, float]:
        return y[:-1].reshape(self.pb.n_control, 3) * _T_SCALE_N, float(y[-1]) * _TF_SCALE_S

    def at(self, y: np.ndarray) -> dict[str, Any]:
        if time.perf_counter() > self.deadline:
            raise SolveTimeout
        key = y.tobytes()
        if self.key != key:
            p, t_f = self.unpack(y)
            g = self.pb.grid(t_f)
            if self.exact:
                gr = self.pb.gradients(p, g)
                self.vals = {"j": gr.j, "c": gr.c, "grad": gr}
            else:
                fl = self.pb.fly(p, g)
                self.vals = {"j": self.pb.cost(fl, g), "c": np.concatenate([fl.xf, fl.vf])}
            self.key = key
        return self.vals

    def fun(self, y: np.ndarray) -> float:
        return self.at(y)["j"] / self.j_scale

    def cons(self, y: np.ndarray) -> np.ndarray:
        return self.at(y)["c"] / _C_SCALE

    def fun_jac(self, y: np.ndarray) -> np.ndarray:
        gr = self.at(y)["grad"]
        return np.concatenate([gr.dj_dp.ravel() * _T_SCALE_N, [gr.dj_dtf * _TF_SCALE_S]]) / (
            self.j_scale
        )

    def cons_jac(self, y: np.ndarray) -> np.ndarray:
        gr = self.at(y)["grad"]
        jac = np.concatenate(
            [gr.dc_dp.reshape(6, -1) * _T_SCALE_N, gr.dc_dtf[:, None] * _TF_SCALE_S], 1
        )
        return jac / _C_SCALE[:, None]


def solve_slsqp(
    pb: Problem,
    deadline: float = math.inf,
    exact_gradients: bool = True,
    maxiter: int = 500,
    ftol: float = 1e-10,
    guess: tuple[np.ndarray, float] | None = None,
) -> SolverOutput:
    """SLSQP from the Sec. 3.1 guess (or `guess` = (thrust (3,) N, t_f s))."""
    lim = pb.limits
    thr0, tf0 = initial_guess(pb.x0, pb.v0, pb.m0, lim) if guess is None else guess
    p0 = np.tile(np.clip(thr0, lim.lo, lim.hi), (pb.n_control, 1))
    y0 = np.concatenate([p0.ravel() / _T_SCALE_N, [tf0 / _TF_SCALE_S]])
    g0 = pb.grid(tf0)
    j_scale = max(pb.cost(pb.fly(p0, g0), g0), 1.0)
    ev = _Evaluator(pb, exact_gradients, j_scale, deadline)
    bounds = [
        (lo / _T_SCALE_N, hi / _T_SCALE_N)
        for _ in range(pb.n_control)
        for lo, hi in zip(lim.lo, lim.hi, strict=True)
    ] + [(TF_MIN_S / _TF_SCALE_S, TF_MAX_S / _TF_SCALE_S)]
    constraint: dict[str, Any] = {"type": "eq", "fun": ev.cons}
    if exact_gradients:
        constraint["jac"] = ev.cons_jac
    try:
        res = minimize(
            ev.fun,
            y0,
            jac=ev.fun_jac if exact_gradients else None,
            method="SLSQP",
            bounds=bounds,
            constraints=[constraint],
            options={"maxiter": maxiter, "ftol": ftol},
        )
    except SolveTimeout:
        return SolverOutput(p0, tf0, 0, "timed out", False)
    p, t_f = ev.unpack(res.x)
    return SolverOutput(p, t_f, int(res.nit), f"SLSQP: {res.message}", bool(res.success))
