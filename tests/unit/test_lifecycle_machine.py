"""pd_core.lifecycle: the managed-node state machine's paths, orders and heartbeats (no ROS)."""

from __future__ import annotations

import pytest

from pd_core import lifecycle as lc


def test_paths_between_primary_states():
    assert lc.path(lc.UNCONFIGURED, lc.ACTIVE) == [lc.CONFIGURE, lc.ACTIVATE]
    assert lc.path(lc.ACTIVE, lc.UNCONFIGURED) == [lc.DEACTIVATE, lc.CLEANUP]
    assert lc.path(lc.INACTIVE, lc.ACTIVE) == [lc.ACTIVATE]
    assert lc.path(lc.ACTIVE, lc.ACTIVE) == []
    assert lc.path(lc.ACTIVE, lc.FINALIZED) == [lc.ACTIVE_SHUTDOWN]
    assert lc.path(lc.UNCONFIGURED, lc.FINALIZED) == [lc.UNCONFIGURED_SHUTDOWN]
    with pytest.raises(ValueError, match="finalized"):
        lc.path(lc.FINALIZED, lc.ACTIVE)
    with pytest.raises(ValueError):
        lc.path(13, lc.ACTIVE)  # a transitional state (activating)


def test_every_path_is_made_of_valid_transitions():
    for start in (lc.UNCONFIGURED, lc.INACTIVE, lc.ACTIVE):
        for goal in (lc.UNCONFIGURED, lc.INACTIVE, lc.ACTIVE, lc.FINALIZED):
            s = start
            for t in lc.path(start, goal):
                assert lc.valid(s, t)
                s = lc.EDGES[(s, t)]
            assert s == goal


def test_valid_transitions_and_labels():
    assert lc.valid(lc.UNCONFIGURED, lc.CONFIGURE)
    assert not lc.valid(lc.UNCONFIGURED, lc.ACTIVATE)
    assert not lc.valid(lc.ACTIVE, lc.CONFIGURE)
    assert not lc.valid(lc.FINALIZED, lc.CONFIGURE)
    assert sorted(lc.valid_from(lc.INACTIVE)) == ["activate", "cleanup", "shutdown"]
    assert lc.valid_from(lc.FINALIZED) == []
    assert lc.state_label(lc.ACTIVE) == "active" and lc.transition_label(99) == "transition 99"


def test_bringup_configures_all_then_activates_in_order_and_tears_down_in_reverse():
    nodes = ["ocp", "policy", "sim"]
    assert lc.bringup(nodes) == [
        ("ocp", lc.CONFIGURE),
        ("policy", lc.CONFIGURE),
        ("sim", lc.CONFIGURE),
        ("ocp", lc.ACTIVATE),
        ("policy", lc.ACTIVATE),
        ("sim", lc.ACTIVATE),
    ]
    assert lc.teardown(nodes) == ["sim", "policy", "ocp"]


def test_heartbeats_watch_only_expected_nodes():
    hb = lc.Heartbeats(timeout_s=2.0)
    hb.beat("sim", 0.0)  # not watched yet: ignored
    assert hb.overdue(100.0) == []
    hb.expect("sim", 10.0)
    hb.expect("policy", 10.0)
    hb.beat("sim", 11.5)
    assert hb.overdue(12.5) == [("policy", 2.5)]
    hb.beat("sim", 11.0)  # an older heartbeat never moves it back
    assert hb.last["sim"] == 11.5
    hb.forget("policy")
    assert hb.overdue(13.0) == []
    assert hb.overdue(14.0) == [("sim", 2.5)]


def test_failure_line_names_who_why_and_what_went_down():
    line = lc.failure_line(
        "pd_sim_node", "no heartbeat for 5.1 s", ["pd_policy_node", "pd_ocp_node"]
    )
    assert line == (
        "pd_sim_node failed (no heartbeat for 5.1 s); deactivated pd_policy_node, pd_ocp_node"
    )
    assert lc.failure_line("a", "b", []).endswith("no other node was active")
