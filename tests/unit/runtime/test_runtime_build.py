"""`pd_core.runtime.build`: one way to build what flies (a policy file, the shipped one, or a
controller, with or without the layer, from the specs of `pd-eval`), and every actor started
afresh per episode through `Runtime.begin_episode(s)` with `Runtime.bare_action` changing
nothing (issue 70, item 2)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pd_core.env import PoweredDescentEnv
from pd_core.runtime.build import MODEL_ENV, ROOT_ENV, build, shipped_policy
from pd_core.runtime.config import RuntimeConfig
from pd_core.runtime.policy_file import SHIPPED_POLICY, PolicyLoadError
from pd_core.teachers.mpc import MPCController
from pd_core.teachers.registry import CONTROLLERS
from pd_core.teachers.zemzev import ZemZevController

ROOT = Path(__file__).resolve().parents[3]
ROBUST = ROOT / "models" / "pd_dqn_robust.pt"
# hovering 60 m up: one step later the lander is within the MPC's continuity of where it was,
# so a teacher that kept its plan would take this state for that plan's continuation
HOVER = np.array([20.0, -10.0, 60.0, 0.5, -0.3, -1.0, 1900.0])


def test_the_shipped_policy_is_found_as_the_node_always_found_it(monkeypatch, tmp_path):
    monkeypatch.delenv(MODEL_ENV, raising=False)
    monkeypatch.setenv(ROOT_ENV, str(ROOT))
    assert shipped_policy() == ROOT / SHIPPED_POLICY
    built = build()
    assert built.policy_file == ROOT / SHIPPED_POLICY and built.label == SHIPPED_POLICY.stem
    assert built.runtime.config == RuntimeConfig.from_dict(built.runtime.metadata["runtime"])
    monkeypatch.setenv(ROOT_ENV, str(tmp_path))  # no file there: the source tree's
    assert shipped_policy() == ROOT / SHIPPED_POLICY
    monkeypatch.setenv(MODEL_ENV, str(tmp_path / "mine.pt"))  # named: taken as it is
    assert shipped_policy() == tmp_path / "mine.pt"
    with pytest.raises(PolicyLoadError, match="mine.pt: no such file"):
        build()


def test_every_spec_builds_what_it_always_built():
    assert build(str(ROBUST)).actor.config == build(ROBUST).actor.config
    assert build(f"bare:{ROBUST}").actor.config.is_off
    assert build(f"layer:{ROBUST}").actor.config == RuntimeConfig()
    alone = build("controller:zemzev")
    assert isinstance(alone.actor, ZemZevController) and alone.label == "controller zemzev"
    assert isinstance(build("bare:controller:zemzev").actor, ZemZevController)
    behind = build("layer:controller:zemzev-vernier")
    assert behind.label == "controller zemzev-vernier + layer"
    assert behind.runtime.config == RuntimeConfig() and behind.runtime.name == "zemzev-vernier"
    changed = build(f"set:touchdown_speed_mps=0:{ROBUST}")
    assert changed.label == "pd_dqn_robust (touchdown_speed_mps=0)"
    assert changed.runtime.config.rules.touchdown_speed_mps == 0.0

    def factory() -> ZemZevController:
        return ZemZevController()

    made = build(factory)
    assert isinstance(made.actor, ZemZevController) and made.label == "factory"


def test_the_keywords_say_what_the_policy_nodes_parameters_say():
    """layer "never"/"always" are the bare:/layer: prefixes; `as_runtime` keeps a controller in
    a Runtime (behind `RuntimeConfig.off()`, whose settings may then change); the one line the
    node logs."""
    never = build(ROBUST, layer="never", as_runtime=True)
    assert never.runtime.config.is_off and never.policy_file == ROBUST
    assert build(ROBUST, layer="always").runtime.config == RuntimeConfig()
    ctl = build("controller:zemzev", layer="never", as_runtime=True)
    assert ctl.runtime.config.is_off and ctl.runtime.name == "zemzev"
    assert ctl.describe().startswith("reference controller zemzev (")
    assert ", no runtime layer, config " in ctl.describe()
    tuned = build("controller:zemzev", settings="touchdown_speed_mps=0", as_runtime=True)
    assert tuned.runtime.config.rules.touchdown_speed_mps == 0.0
    assert "runtime settings touchdown_speed_mps=0" in tuned.describe()
    line = build(ROBUST, layer="always", as_runtime=True).describe()
    assert line.startswith(f"{ROBUST} (network ") and ", runtime layer on, config " in line
    assert (
        build(ROBUST, layer="never")
        .describe()
        .endswith(f"no runtime layer, config {never.runtime.config.digest()})")
    )


def test_what_cannot_be_built_is_refused_in_one_line():
    for spec, says in (
        ("controller:nope", "unknown controller 'nope'; choose from " + ", ".join(CONTROLLERS)),
        ("set:nav_filter=0:controller:zemzev", "controller zemzev has no runtime layer"),
        (f"set:gain=1:{ROBUST}", "'gain' is unknown"),
        ("models/nothing_here.pt", "no such file"),
    ):
        with pytest.raises(PolicyLoadError, match=says) as err:
            build(spec)
        assert "\n" not in str(err.value)
    with pytest.raises(PolicyLoadError, match="flies without a runtime layer"):
        _ = build("controller:zemzev").runtime
    with pytest.raises(ValueError, match="layer must be one of"):
        build(ROBUST, layer="maybe")


def test_a_path_is_a_file_never_a_spec(tmp_path):
    with pytest.raises(PolicyLoadError, match="no such file"):
        build(Path("controller:zemzev"))


def test_an_mpc_teacher_flown_twice_decides_its_first_step_alike():
    """`Runtime.begin_episode` starts the teacher afresh: without it, the second flight's first
    state would continue the first flight's plan (a hovering lander is where its plan said it
    would be) and be answered by a warm re-plan, not the first decision."""
    rt = build("layer:controller:mpc-fuel").runtime
    teacher = rt.actor
    assert isinstance(teacher, MPCController)
    rt.begin_episode()
    first = rt.step(HOVER)
    assert len(teacher.stats.cold) == 1
    rt.begin_episode()
    assert rt.step(HOVER) == first
    assert len(teacher.stats.cold) == 2 and len(teacher.stats.warm) == 0
    # what begin_episode prevents: the same state without it continues the plan
    assert rt.step(HOVER) != first and len(teacher.stats.warm) == 1


def test_begin_episodes_starts_every_row_of_a_batch_afresh():
    rt = build("layer:controller:mpc-fuel").runtime
    states = np.stack([HOVER, HOVER + [5.0, 0, 40.0, 0, 0, 0, 0]])
    rt.begin_episodes(2)
    first, decisions = rt.step_rows(states, np.arange(2))
    rt.begin_episodes(2)
    again, _ = rt.step_rows(states, np.arange(2))
    np.testing.assert_array_equal(again, first)
    assert len(rt.actor.stats.cold) == 4 and len(rt.actor.stats.warm) == 0


@pytest.mark.parametrize("name", ["mpc-fuel", "mpc-energy"])
def test_bare_action_leaves_the_next_decision_unchanged(name: str):
    """An MPC teacher's own action on the state it is about to be asked about (what
    `bare_action` answered by re-planning in place, before) changes none of its plans: the
    flight decides step for step as a twin's that is never asked."""
    rt = build(f"layer:controller:{name}").runtime
    twin = build(f"layer:controller:{name}").runtime
    env = PoweredDescentEnv(disturbance=True)
    _, info = env.reset(seed=3, options={"initial_state": HOVER})
    rt.begin_episode()
    twin.begin_episode()
    for _ in range(6):
        s = info["state"]
        proposed = rt.bare_action(s)
        action, decision = rt.step(s)
        assert (action, decision) == twin.step(s)
        assert proposed == decision.proposed  # the same plan, the same proposal
        _, _, term, trunc, info = env.step(action)
        assert not (term or trunc)
    assert rt.actor.stats.warm and len(rt.actor.stats.warm) == len(twin.actor.stats.warm)


def test_a_network_proposes_on_a_nominal_engine_and_keeps_the_fraction_handed_over():
    net = build(ROOT / "models" / "pd_dqn_adapt.pt").runtime.actor
    assert net.takes_thrust_fraction
    s, weak = np.tile(HOVER, (2, 1)), np.array([0.8, 0.8])
    nominal = net.q_values(s)  # nothing handed over
    net.take_thrust_fraction(weak)
    want = net.q_values(s)
    assert not np.array_equal(want, nominal)
    net.take_thrust_fraction(weak)
    np.testing.assert_array_equal(net.propose(s), nominal.argmax(-1))
    np.testing.assert_array_equal(net.q_values(s), want)  # the fraction was still there
