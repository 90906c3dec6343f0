"""The Gymnasium env, the vector env and their agreement."""

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from pd_core.actions import DEFAULT_ACTIONS
from pd_core.config import RL_THRUST, STATE_SCALE, TABLE3
from pd_core.env import PoweredDescentEnv
from pd_core.lander import Lander, Status
from pd_core.state import check_state
from pd_core.vector_env import PoweredDescentVectorEnv, make_vector_env

START = [600.0, -200.0, 2500.0, -40.0, 10.0, -80.0, 2000.0]


def test_gymnasium_env_checker_passes():
    check_env(PoweredDescentEnv(), skip_render_check=True)


def test_the_lander_without_gymnasium_flies_the_envs_episodes_to_the_bit():
    # seeded resets, then an unseeded one that continues the same generator, as Gymnasium's
    env, lander = PoweredDescentEnv(), Lander()
    actions = np.random.default_rng(5).integers(0, DEFAULT_ACTIONS.n, size=120)
    for seed in (11, None, 12345, None):
        obs_e, info_e = env.reset(seed=seed)
        obs_l, info_l = lander.reset(seed=seed)
        np.testing.assert_array_equal(obs_e, obs_l)
        for a in actions:
            out_e, out_l = env.step(int(a)), lander.step(int(a))
            np.testing.assert_array_equal(out_e[0], out_l[0])
            assert out_e[1:4] == out_l[1:4]
            np.testing.assert_array_equal(out_e[4]["state"], out_l[4]["state"])
            if out_e[2] or out_e[3]:
                break
        assert env.time_s == lander.time_s > 0


def test_action_mapping_is_linear_over_rl_limits():
    assert DEFAULT_ACTIONS.n == 147
    np.testing.assert_array_equal(DEFAULT_ACTIONS.thrust(0), RL_THRUST.lo)
    np.testing.assert_array_equal(DEFAULT_ACTIONS.thrust(146), RL_THRUST.hi)
    # middle of i and j, k level 1 of 3: zero lateral thrust, 6.5 kN up
    a = DEFAULT_ACTIONS.levels_to_action(np.array([3, 3, 1]))
    np.testing.assert_allclose(DEFAULT_ACTIONS.thrust(a), [0.0, 0.0, 6500.0])


def test_observation_is_scaled_state():
    env = PoweredDescentEnv()
    obs, info = env.reset(seed=0, options={"initial_state": START})
    np.testing.assert_allclose(obs, np.array(START) * STATE_SCALE, rtol=1e-6)
    np.testing.assert_array_equal(info["state"], START)


def test_reset_samples_table3_and_is_seeded():
    env = PoweredDescentEnv()
    states = np.array([env.reset(seed=s)[1]["state"] for s in range(300)])
    assert np.all(states >= TABLE3.lo) and np.all(states <= TABLE3.hi)
    assert np.ptp(states[:, 0]) > 0.9 * (TABLE3.hi[0] - TABLE3.lo[0])
    np.testing.assert_array_equal(env.reset(seed=5)[1]["state"], env.reset(seed=5)[1]["state"])


def test_free_fall_crashes_and_terminates_below_1cm():
    env = PoweredDescentEnv(disturbance=False)
    env.reset(options={"initial_state": START})
    zero_thrust = DEFAULT_ACTIONS.levels_to_action(np.array([3, 3, 0]))
    for _ in range(1000):
        _, _, term, trunc, info = env.step(int(zero_thrust))
        if term or trunc:
            break
    assert term and not trunc
    assert info["state"][2] < 0.01
    assert info["status"] == Status.CRASHED and not info["landed"]


def test_time_limit_truncates_not_terminates():
    env = PoweredDescentEnv(disturbance=False, max_time_s=2.0)
    env.reset(options={"initial_state": START})
    steps = 0
    for _ in range(20):
        _, _, term, trunc, info = env.step(146)
        steps += 1
        if trunc or term:
            break
    assert steps == 10 and trunc and not term and info["status"] == Status.OUT_OF_TIME


def test_vector_env_equals_single_envs_with_same_seeds():
    n = 4
    venv = PoweredDescentVectorEnv(n, autoreset=False)
    venv.reset(seed=100)
    envs = [PoweredDescentEnv() for _ in range(n)]
    for i, e in enumerate(envs):
        e.reset(seed=100 + i)
    np.testing.assert_array_equal(venv.states, np.array([e.state for e in envs]))
    rng = np.random.default_rng(0)
    for _ in range(250):
        a = rng.integers(0, 147, n)
        live = venv.active
        _, vr, vterm, _, vinfo = venv.step(a)
        for i, e in enumerate(envs):
            if not live[i]:  # an ended sub-env is frozen until the next reset
                assert vr[i] == 0.0 and not vterm[i]
                continue
            _, r, term, _, info = e.step(int(a[i]))
            np.testing.assert_allclose(vinfo["state"][i], info["state"], rtol=1e-13, atol=1e-9)
            assert vr[i] == pytest.approx(r, abs=1e-12)
            assert bool(vterm[i]) == term


def test_vector_env_autoreset_reports_final_state():
    venv = PoweredDescentVectorEnv(2, disturbance=False, max_time_s=1.0)
    venv.reset(seed=0)
    for _ in range(5):
        obs, _, term, trunc, info = venv.step(np.array([73, 73]))
    assert trunc.all() and not term.any()
    assert "final_state" in info
    np.testing.assert_allclose(obs, venv.states * STATE_SCALE, rtol=1e-6)
    assert (venv.steps == 0).all()


def test_nan_and_absurd_states_are_refused():
    env = PoweredDescentEnv()
    bad = [np.nan, 0, 2500, 0, 0, -80, 2000]
    with pytest.raises(ValueError, match="NaN"):
        env.reset(options={"initial_state": bad})
    with pytest.raises(ValueError, match="mass"):
        check_state([0, 0, 2500, 0, 0, -80, -5])
    with pytest.raises(ValueError, match="velocity"):
        check_state([0, 0, 2500, 0, 0, -8e6, 2000])
    with pytest.raises(ValueError, match="7 entries"):
        check_state([0, 0, 2500])


@pytest.mark.parametrize("slot", range(7))
@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf, 2e6, -2e6])
def test_one_state_is_refused_as_a_batch_of_it_is(slot, value):
    """A single state takes a plain-float fast path: every fault a batch row is refused for
    (NaN, inf, a bound in any slot) is refused there too, with the same line."""
    state = np.array([0.0, 0.0, 2500.0, 0.0, 0.0, -80.0, 2000.0])
    state[slot] = value
    with pytest.raises(ValueError) as batch:
        check_state(np.stack([state, state]))
    with pytest.raises(ValueError) as one:
        check_state(state)

    def reason(e: pytest.ExceptionInfo) -> str:  # the line without the values it quotes
        return str(e.value).split(":")[0].split(" got ")[0]

    assert reason(one) == reason(batch)
    good = check_state(np.array([1.0, -2.0, 3.0, 4.0, -5.0, 6.0, 1e6]))
    np.testing.assert_array_equal(good, [1.0, -2.0, 3.0, 4.0, -5.0, 6.0, 1e6])


@pytest.mark.parametrize("action", [-1, 147, 3.5, "7"])
def test_out_of_range_actions_are_refused(action):
    env = PoweredDescentEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(action)
    venv = PoweredDescentVectorEnv(2)
    venv.reset(seed=0)
    with pytest.raises(ValueError):
        venv.step(np.array([0, action]) if not isinstance(action, str) else np.array([0, 999]))


def test_without_autoreset_a_fixed_set_of_episodes_flies_and_ended_ones_freeze():
    venv = make_vector_env(3, disturbance=False, max_time_s=2.0, autoreset=False)
    venv.reset(seed=0)
    free_fall = DEFAULT_ACTIONS.levels_to_action(np.array([3, 3, 0]))
    steps = 0
    while venv.active.any():
        _, _, term, trunc, info = venv.step(np.full(3, free_fall))
        steps += 1
    assert steps == 10 and trunc.all() and not term.any()
    frozen = venv.states.copy()
    _, r, term, trunc, info = venv.step(np.full(3, free_fall))
    np.testing.assert_array_equal(venv.states, frozen)
    assert not (term | trunc | info["active"]).any() and (r == 0).all()
    assert (venv.steps == 10).all()
