"""The LPs of the fuel objective through HiGHS directly (`highspy`): one model re-used across
solves, passed as arrays, optionally from the last basis (`LPSolver`)."""

from __future__ import annotations

import highspy
import numpy as np


def solve_lp(
    cost: np.ndarray,
    a_eq: np.ndarray,
    b_eq: np.ndarray,
    lb: np.ndarray,
    ub: np.ndarray,
    highs: highspy.Highs | LPSolver | None = None,
    row_hi: np.ndarray | None = None,
) -> np.ndarray | None:
    """argmin cost @ x s.t. a_eq x = b_eq, lb <= x <= ub (dense a_eq with few rows), or None.
    With `row_hi`, the rows are b_eq <= a_eq x <= row_hi instead. `highs`: a solver object to
    re-use (its model is replaced; building one costs ~0.3 ms), or an `LPSolver`, which also
    starts from the basis of its last LP of the same shape.

    HiGHS through `highspy` directly: the same solver as scipy's linprog(method="highs") without
    its per-call validation and presolve, 3-10x faster on these 100-500 column LPs
    (bench/mpc_speed.py).
    """
    solver = highs if isinstance(highs, LPSolver) else LPSolver(highs, warm=False)
    return solver.solve(cost, a_eq, b_eq, b_eq if row_hi is None else row_hi, lb, ub)


class LPSolver:
    """One HiGHS object for a sequence of LPs (the receding-horizon teacher's re-plans): the
    model is passed as arrays (no `HighsLp` built in Python, whose attribute copies cost as
    much as the solve), and with `warm` an LP of the same shape as the last one starts from its
    optimal basis (a re-plan's LP is the last one moved by one step: a few pivots)."""

    def __init__(self, highs: highspy.Highs | None = None, warm: bool = True) -> None:
        self.highs = new_highs() if highs is None else highs
        self.warm = warm
        self._basis: highspy.HighsBasis | None = None
        self._shape: tuple[int, int] = (-1, -1)
        self._index: dict[tuple[int, int], tuple[np.ndarray, ...]] = {}
        self.iterations = 0  # simplex iterations of the last solve

    def solve(
        self,
        cost: np.ndarray,
        a: np.ndarray,
        row_lo: np.ndarray,
        row_hi: np.ndarray,
        lb: np.ndarray,
        ub: np.ndarray,
    ) -> np.ndarray | None:
        """argmin cost @ x s.t. row_lo <= a x <= row_hi, lb <= x <= ub (a dense), or None."""
        rows, cols = a.shape
        if (rows, cols) not in self._index:
            self._index[rows, cols] = (
                np.arange(0, rows * cols, rows, dtype=np.int32),
                np.tile(np.arange(rows, dtype=np.int32), cols),
                np.zeros(cols, dtype=np.int32),  # all continuous (an empty array is refused)
            )
        start, index, integrality = self._index[rows, cols]
        h = self.highs
        h.passModel(
            cols,
            rows,
            rows * cols,
            1,  # MatrixFormat.kColwise
            1,  # ObjSense.kMinimize
            0.0,
            np.ascontiguousarray(cost, dtype=float),
            np.ascontiguousarray(lb, dtype=float),
            np.ascontiguousarray(ub, dtype=float),
            np.ascontiguousarray(row_lo, dtype=float),
            np.ascontiguousarray(row_hi, dtype=float),
            start,
            index,
            np.ascontiguousarray(a.T, dtype=float).reshape(-1),
            integrality,
        )
        if self.warm and self._basis is not None and self._shape == (rows, cols):
            h.setBasis(self._basis)
        h.run()
        self.iterations = int(h.getInfo().simplex_iteration_count)
        if h.getModelStatus() != highspy.HighsModelStatus.kOptimal:
            self._basis = None
            return None
        if self.warm:
            self._basis, self._shape = h.getBasis(), (rows, cols)
        return np.asarray(h.getSolution().col_value)


def new_highs() -> highspy.Highs:
    """A quiet HiGHS without presolve (6 dense rows: presolve costs 5x the solve)."""
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("presolve", "off")
    return h
