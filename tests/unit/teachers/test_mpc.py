"""pd_core.teachers.mpc and pd_core.demonstrations.teacher_flown: the closed-loop teacher lands,
falls back safely, and its
demonstrations and DAgger labels are what they claim to be."""

from __future__ import annotations

import numpy as np
import pytest

from pd_core.demonstrations.open_loop import table1_initial_states
from pd_core.demonstrations.teacher_flown import mpc_demonstrations
from pd_core.episodes import rollout
from pd_core.teachers.mpc import MPCController, MPCParams
from pd_core.teachers.registry import CONTROLLERS, make_controller
from pd_core.teachers.zemzev import ZemZevController

CASES = table1_initial_states()


# All 33 land with both objectives (re-checked on the issue-10 revision: worst k-velocity
# -1.26 m/s fuel, -1.30 m/s energy); the suite flies every 4th case to stay short. Wall time
# under load can be 10x the CPU time, hence the timeout.
@pytest.mark.slow
@pytest.mark.timeout(900)
@pytest.mark.parametrize(("objective", "cases"), [("fuel", CASES[::4]), ("energy", CASES[::4])])
def test_teacher_lands_the_table1_cases_in_the_disturbed_env(
    objective: str, cases: np.ndarray
) -> None:
    ctl = make_controller(f"mpc-{objective}")
    ro = rollout(ctl, len(cases), seed=0, initial_states=cases)
    assert ro.landed.all(), np.flatnonzero(~ro.landed)
    assert ro.final_states[:, 5].min() >= -2.0  # k-velocity at touchdown, m/s (Eq. 12 limit)
    # it flew on its plans, not on the fallback: a cold plan per episode, warm re-plans after
    assert len(ctl.stats.cold) == len(cases)
    assert len(ctl.stats.warm) > 0.8 * ro.steps.sum()


def test_registered_as_controllers_with_the_zemzev_interface() -> None:
    assert {"zemzev", "mpc-fuel", "mpc-energy"} <= set(CONTROLLERS)
    ctl = make_controller("mpc-energy")
    assert ctl.name == "mpc-energy"
    s = CASES[3]
    a = ctl.act(s)
    assert 0 <= a < 147 and ctl.act_batch(s[None]).shape == (1,)
    np.testing.assert_array_equal(ctl.thrust(a), ctl.actions.thrust(a))
    with pytest.raises(ValueError, match="unknown controller"):
        make_controller("mpc-nope")


def test_near_the_pad_and_without_a_solution_the_fallback_flies() -> None:
    zz = ZemZevController()
    ctl = MPCController(MPCParams(objective="fuel"), zz)
    near_pad = np.array([0.5, -0.3, 1.5, 0.1, 0.0, -1.0, 1600.0])  # below the 2 m gate
    hopeless = np.array([0.0, 0.0, 30.0, 0.0, 0.0, -90.0, 1100.0])  # cannot stop in 30 m
    for s in (near_pad, hopeless):
        assert ctl.act_batch(s[None])[0] == zz.act(s)
    assert ctl.stats.fallback_steps == 2


def test_actions_depend_only_on_each_episodes_own_history() -> None:
    # Plans are matched to states, not rows: episodes flown together, or alone, or as chunks of
    # a process pool, get the same actions (rollout drops finished rows, shifting the rest).
    # Short flights (from 300-400 m) keep the test quick.
    init = np.array(
        [
            [60.0, -40.0, 300.0, -5.0, 3.0, -20.0, 1700.0],
            [-80.0, 20.0, 400.0, 6.0, 0.0, -25.0, 1800.0],
            [10.0, 90.0, 350.0, 0.0, -8.0, -15.0, 1650.0],
        ]
    )
    kw = {"initial_states": init}
    together = mpc_demonstrations(3, 11, "energy", workers=1, chunk=3, **kw)
    alone = mpc_demonstrations(3, 11, "energy", workers=1, chunk=1, **kw)
    pooled = mpc_demonstrations(3, 11, "energy", workers=2, chunk=2, **kw)
    for d in (alone, pooled):
        for key in ("states", "actions", "next_states", "dones", "episode"):
            np.testing.assert_array_equal(d[key], together[key])
    n = len(together["actions"])
    assert together["states"].shape == together["next_states"].shape == (n, 7)
    assert together["dones"].sum() == 3 and set(together["episode"]) == {0, 1, 2}
    same = together["episode"][1:] == together["episode"][:-1]  # consecutive steps of an episode
    np.testing.assert_array_equal(together["next_states"][:-1][same], together["states"][1:][same])
    assert float(together["success_rate"]) == 1.0
