"""One decision is three calls (`Runtime.step_rows`: `LatencyCompensator.predict_scaled`, the
actor, `rules_and_record`); they must fly exactly what the runtime layer's stages, called one by
one, fly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pd_core.dispersions import load_scenarios
from pd_core.runtime.decision import BRAKE, GUARD, HANDOVER, NETWORK
from pd_core.runtime.latency import LatencyCompensator
from pd_core.runtime.policy_file import load_policy
from pd_core.runtime.rules import decide
from pd_core.vector_env import make_vector_env

OCP = Path(__file__).resolve().parents[3] / "models" / "pd_dqn_ocp.pt"


def test_the_fused_decision_flies_what_the_stages_composed_fly():
    """64 landers of the `broad` campaign's scenarios (delay, thrust shortfall, navigation noise,
    light landers, the wide box) for 60 s, every step decided both ways: the actions, their
    sources, the delay and thrust fraction counted on and the filter's state agree to the bit,
    and every rule fired somewhere."""
    rt = load_policy(OCP)
    cfg = rt.config
    ref = LatencyCompensator(cfg.latency, cfg.nav_filter)
    env = make_vector_env(64, autoreset=False, dispersions=load_scenarios("broad"))
    _, info = env.reset(seed=4_400_000)
    rt.begin_episodes(64)
    ref.reset(64)
    seen = np.zeros(4, dtype=int)
    actions = np.zeros(64, dtype=np.int64)
    active = env.active
    for _ in range(300):
        if not active.any():
            break
        rows = np.flatnonzero(active)
        obs = info["observed_state"][active]
        got, d = rt.step_rows(obs, rows)
        decided = ref.predict(obs, rows)
        scale = ref.vertical_thrust_scale(rows)
        proposed = rt.actor.act_batch(decided)
        want, source, frac, limit = decide(rt._rules, proposed, decided, rt.fallback, scale)
        ref.record(rows, rt._rules.table_n[want])
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(d.proposed, proposed)
        np.testing.assert_array_equal(d.source, source)
        np.testing.assert_array_equal(d.thrust_gain_bound, frac)
        np.testing.assert_array_equal(d.brake_limit, limit)
        np.testing.assert_array_equal(d.delay_steps, ref.delay_steps[rows])
        np.testing.assert_array_equal(d.nav_filter_engaged, ref.nav.engaged[rows])
        seen += np.bincount(d.source, minlength=4)
        actions[active] = got
        _, _, _, _, info = env.step(actions)
        active = info["active"]
    assert all(seen[k] > 0 for k in (NETWORK, BRAKE, GUARD, HANDOVER)), seen
    assert seen[HANDOVER] < seen[NETWORK]


def test_an_invalid_observation_is_refused_and_leaves_the_memory_as_it_was():
    rt = load_policy(OCP)
    s = np.array([0.0, 0.0, 1000.0, 0.0, 0.0, -50.0, 2000.0])
    rt.step(s)
    before = rt.latency._last.copy(), rt.latency._issued.copy(), dict(rt.counts)
    for bad, words in ((np.r_[s[:6], -1.0], "mass"), (np.r_[np.nan, s[1:]], "NaN")):
        with pytest.raises(ValueError, match=words):
            rt.step(bad)
    np.testing.assert_array_equal(rt.latency._last, before[0])
    np.testing.assert_array_equal(rt.latency._issued, before[1])
    assert rt.counts == before[2]
    with pytest.raises(ValueError, match="7 entries"):
        rt.step_rows(np.zeros((1, 6)), np.zeros(1, dtype=np.int64))
