"""pd_core.discretise (Eqs. 5-7) and pd_core.demonstrations.open_loop (file format)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pd_core import discretise as disc
from pd_core import ocp
from pd_core.demonstrations.open_loop import (
    DemoSet,
    load_demos,
    runs_to_demos,
    save_demos,
    table1_initial_states,
)


@pytest.fixture(scope="module")
def results() -> list[ocp.OCPResult]:
    return [ocp.solve(s[0:3], s[3:6], s[6]) for s in table1_initial_states()]


def test_eq5_picks_the_level_above_or_below() -> None:
    n = np.array([7.0, 7.0, 3.0])
    a = np.array([0.55, 0.55, 0.7])
    assert disc.eq5_levels(a, np.array([1.0, -1.0, 0.0]), n).tolist() == [4, 3, 1]
    assert disc.eq5_levels(np.ones(3), np.ones(3), n).tolist() == [6, 6, 2]  # clipped


def test_7x7x3_demonstrations_land(results: list[ocp.OCPResult]) -> None:
    runs = disc.discretise_batch(results, (7, 7, 3))
    rate = np.mean([r.landed for r in runs])
    # Issue 3 asks >= 75 % (paper 81.8 %). Literal Eqs. 5-7 with the "lowest" reading of Eq. 7:
    # 87.9 % (29 of 33); the "ocp_time" reading lands 63.6 %.
    assert rate >= 0.75
    for r in runs:
        assert r.terminated and r.states[-1, 2] < 0.01
        assert r.actions.dtype == np.int64 and np.all((r.actions >= 0) & (r.actions < 147))


def test_single_equals_batch(results: list[ocp.OCPResult]) -> None:
    one = disc.discretise(results[5])
    batch = disc.discretise_batch(results[:6])[5]
    np.testing.assert_array_equal(one.actions, batch.actions)
    np.testing.assert_allclose(one.states, batch.states)


def test_demo_file_round_trip_and_refusals(results: list[ocp.OCPResult], tmp_path) -> None:
    demos = runs_to_demos(disc.discretise_batch(results[:3]))
    path = tmp_path / "d.npz"
    save_demos(path, demos, {"made_by": "test"})
    back, meta = load_demos(path)
    for f in DemoSet._fields:
        np.testing.assert_array_equal(getattr(back, f), getattr(demos, f))
    assert meta["n_per_axis"] == [7, 7, 3] and meta["made_by"] == "test"
    np.testing.assert_allclose(back.next_states[:-1][~back.dones[:-1]][:5], back.states[1:6])
    with pytest.raises(ValueError, match="n_per_axis"):
        load_demos(path, n_per_axis=(9, 9, 3))
    with pytest.raises(ValueError, match="does not exist"):
        load_demos(tmp_path / "missing.npz")
    (tmp_path / "bad.npz").write_bytes(b"garbage")
    with pytest.raises(ValueError, match="corrupt"):
        load_demos(tmp_path / "bad.npz")
    arrays = dict(np.load(path))
    meta["dt_s"] = 0.1
    arrays["metadata"] = np.array(json.dumps(meta))
    np.savez(tmp_path / "dt.npz", **arrays)
    with pytest.raises(ValueError, match="dt_s"):
        load_demos(tmp_path / "dt.npz")


def test_lowest_hindsight_is_a_fixed_point(results: list[ocp.OCPResult]) -> None:
    """Eq. 7, "lowest": the shifted episode ends exactly at x = 0, so relabelling its final state
    again would move nothing; "ocp_time" ends there only when nothing touches down early."""
    runs = disc.discretise_batch(results, (7, 7, 3), hindsight="lowest")
    for r in runs:
        np.testing.assert_allclose(r.final_state[0:3], 0.0, atol=1e-9)
    ocp_time = disc.discretise_batch(results, (7, 7, 3), hindsight="ocp_time")
    assert np.mean([r.landed for r in runs]) > np.mean([r.landed for r in ocp_time])
    with pytest.raises(ValueError, match="hindsight"):
        disc.discretise_batch(results[:1], hindsight="nope")
