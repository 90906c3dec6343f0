"""DQN pieces: replay memories, epsilon, target cadence, TD targets (Eq. 11), n-step, config."""

from __future__ import annotations

import argparse
import copy
from dataclasses import replace

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from pd_core.dqn.agent import DQNAgent, epsilon_at, large_margin_loss, td_targets
from pd_core.dqn.config import PRESETS, TrainConfig, add_arguments, field_docs, from_args, preset
from pd_core.dqn.network import QNetwork
from pd_core.dqn.replay import (
    DemoMemory,
    NStepCollector,
    ReplayMemory,
    ReplaySample,
    nstep_from_episodes,
)

torch.set_num_threads(1)


def _fill(mem: ReplayMemory, start: int, n: int) -> None:
    v = np.arange(start, start + n, dtype=np.float32)
    obs = np.repeat(v[:, None], 7, axis=1)
    mem.add(obs, np.arange(n) % 147, v, obs + 1, np.full(n, 0.5))


def test_replay_capacity_is_fifo():
    mem = ReplayMemory(5)
    _fill(mem, 0, 3)
    assert len(mem) == 3
    _fill(mem, 3, 4)  # 7 transitions into 5 slots: 0 and 1 are gone
    assert len(mem) == 5
    assert sorted(mem.rewards.tolist()) == [2.0, 3.0, 4.0, 5.0, 6.0]
    _fill(mem, 100, 12)  # more than the capacity in one batch keeps the newest
    assert sorted(mem.rewards.tolist()) == [107.0, 108.0, 109.0, 110.0, 111.0]


def test_replay_sample_is_a_namedtuple_of_tensors():
    mem = ReplayMemory(10)
    _fill(mem, 0, 10)
    s = mem.sample(4, np.random.default_rng(0))
    assert isinstance(s, ReplaySample)
    assert s.obs.shape == (4, 7) and s.obs.dtype == torch.float32
    assert s.actions.dtype == torch.int64
    assert not s.demo.any()
    with pytest.raises(ValueError):
        ReplayMemory(3).sample(1, np.random.default_rng(0))


def test_demo_memory_is_never_overwritten():
    v = np.arange(6, dtype=np.float32)
    obs = np.repeat(v[:, None], 7, axis=1)
    demo = DemoMemory.fill(obs, np.arange(6), v, obs, np.zeros(6))
    before = {k: getattr(demo, k).copy() for k in ("obs", "actions", "rewards", "discounts")}
    with pytest.raises(RuntimeError):
        demo.add(obs, np.arange(6), v, obs, np.zeros(6))
    s = demo.sample(50, np.random.default_rng(1))
    assert s.demo.all()
    for k, arr in before.items():
        np.testing.assert_array_equal(getattr(demo, k), arr)
    # round trip through a checkpoint keeps it sealed
    d2 = DemoMemory(1)
    d2.load_state_dict(demo.state_dict())
    np.testing.assert_array_equal(d2.obs, demo.obs)
    with pytest.raises(RuntimeError):
        d2.add(obs, np.arange(6), v, obs, np.zeros(6))


def test_epsilon_schedule_is_linear_per_finished_episode():
    cfg = preset("paper-agent1")
    assert epsilon_at(0, cfg) == pytest.approx(0.6)
    assert epsilon_at(2000, cfg) == pytest.approx(0.3)
    assert epsilon_at(4000, cfg) == pytest.approx(0.0)
    assert epsilon_at(9000, cfg) == pytest.approx(0.0)
    cfg2 = replace(cfg, epsilon0=0.2, epsilon_final=0.1, epsilon_episodes=10)
    assert epsilon_at(5, cfg2) == pytest.approx(0.15)


def _tiny_cfg(**kw) -> TrainConfig:
    return replace(TrainConfig(), hidden=(8,), optimizer="adam", lr=1e-2, **kw)


def _batch(n: int = 6, seed: int = 0) -> ReplaySample:
    g = torch.Generator().manual_seed(seed)
    return ReplaySample(
        torch.randn(n, 7, generator=g),
        torch.randint(0, 147, (n,), generator=g),
        torch.randn(n, generator=g),
        torch.randn(n, 7, generator=g),
        torch.full((n,), 0.9),
        torch.zeros(n, dtype=torch.bool),
    )


def test_target_network_copied_every_n_t_updates():
    torch.manual_seed(0)
    agent = DQNAgent(_tiny_cfg(target_period=3))
    b = _batch()

    def same() -> bool:
        return all(
            torch.equal(a, c)
            for a, c in zip(
                agent.q.state_dict().values(), agent.q_target.state_dict().values(), strict=True
            )
        )

    assert same()
    agent.update(b)
    assert not same()
    agent.update(b)
    assert not same()
    agent.update(b)  # 3rd update: copy
    assert same()
    agent.update(b)
    assert not same()
    agent.update(b)
    agent.update(b)  # 6th
    assert same()


def test_weight_average_moves_one_minus_decay_of_the_way_each_update():
    torch.manual_seed(0)
    agent = DQNAgent(_tiny_cfg(weight_average=0.9))
    assert agent.q_avg is not None and agent.policy_net is agent.q_avg
    before = [p.clone() for p in agent.q_avg.parameters()]
    agent.update(_batch())  # the online network moves; the average not yet
    for a, b in zip(agent.q_avg.parameters(), before, strict=True):
        assert torch.equal(a, b)
    agent.average_step()
    for a, b, w in zip(agent.q_avg.parameters(), before, agent.q.parameters(), strict=True):
        torch.testing.assert_close(a, 0.9 * b + 0.1 * w, rtol=1e-6, atol=1e-7)
        assert not torch.equal(a, w)
    agent.reset_average()
    for a, w in zip(agent.q_avg.parameters(), agent.q.parameters(), strict=True):
        assert torch.equal(a, w)
    # without an average the online network flies and the step does nothing
    plain = DQNAgent(_tiny_cfg())
    assert plain.q_avg is None and plain.policy_net is plain.q
    plain.average_step()


def test_update_is_the_per_tensor_arithmetic_to_the_bit():
    """The agent's update (functional forward, foreach Adam, cached parameter lists, one
    foreach lerp for the average) gives the same weights, to the bit, as the plain per-tensor
    loop: module calls, torch's CPU default Adam, and one lerp_ per parameter. A change that
    moved a bit here would change every shipped file's recipe output."""
    cfg = replace(
        _tiny_cfg(near_pad=True, grad_clip=0.5, weight_average=0.9, double_dqn=True),
        hidden=(16, 8),
        loss="huber",
        margin=1.0,
        target_period=7,
    )
    torch.manual_seed(0)
    agent = DQNAgent(cfg)
    q, qt, qa = (copy.deepcopy(n) for n in (agent.q, agent.q_target, agent.q_avg))
    opt = torch.optim.Adam(q.parameters(), lr=cfg.lr, eps=1.5e-4, foreach=False)

    def plain(net: QNetwork, x: torch.Tensor) -> torch.Tensor:
        return net.net(net.inputs(x))

    for k in range(30):
        b = _batch(32, seed=k)
        b = b._replace(demo=torch.arange(32) % 2 == 0)
        agent.update(b)
        agent.average_step()
        q_all = plain(q, b.obs)
        qsa = q_all.gather(1, b.actions[:, None]).squeeze(1)
        with torch.no_grad():
            a_next = plain(q, b.next_obs).argmax(dim=1, keepdim=True)
            target = b.rewards + b.discounts * plain(qt, b.next_obs).gather(1, a_next).squeeze(1)
        loss = F.smooth_l1_loss(qsa, target) + cfg.margin * large_margin_loss(
            q_all[b.demo], b.actions[b.demo], cfg.margin_value
        )
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(list(q.parameters()), cfg.grad_clip)
        opt.step()
        if (k + 1) % cfg.target_period == 0:
            qt.load_state_dict(q.state_dict())
        with torch.no_grad():
            for w_avg, w in zip(qa.parameters(), q.parameters(), strict=True):
                w_avg.lerp_(w, 1.0 - cfg.weight_average)
    for mine, ref in ((agent.q, q), (agent.q_avg, qa)):
        for (name, a), b in zip(mine.state_dict().items(), ref.state_dict().values(), strict=True):
            assert torch.equal(a, b), name
    x = torch.randn(5, 7)
    assert torch.equal(agent.q(x), plain(agent.q, x))


def _linear_net(weight: list[list[float]], bias: list[float]) -> QNetwork:
    net = QNetwork(2, 3, hidden=(), activation="tanh")
    with torch.no_grad():
        net.net[0].weight.copy_(torch.tensor(weight))
        net.net[0].bias.copy_(torch.tensor(bias))
    return net


def test_td_target_hand_computed_terminal_and_not():
    # Q_T(s') = W s' + b with W = [[1, 0], [0, 1], [1, 1]], b = 0
    target = _linear_net([[1, 0], [0, 1], [1, 1]], [0, 0, 0])
    rewards = torch.tensor([1.0, 2.0, -0.5])
    next_obs = torch.tensor([[1.0, 2.0], [3.0, -1.0], [0.5, 0.5]])
    # row 0: max(1, 2, 3) = 3, not terminal -> 1 + 0.926 * 3
    # row 1: terminal -> 2
    # row 2: max(0.5, 0.5, 1) = 1, truncated 3-step bootstrap -> -0.5 + 0.926^3 * 1
    g = 0.926
    disc = torch.tensor([g, 0.0, g**3])
    y = td_targets(target, None, rewards, next_obs, disc)
    np.testing.assert_allclose(y.numpy(), [1 + g * 3, 2.0, -0.5 + g**3], rtol=1e-6)
    # double DQN: the online net picks the action, the target net values it
    online = _linear_net([[0, 0], [1, 0], [0, 0]], [0, 0, 0])  # argmax: action 1 when x > 0
    y2 = td_targets(target, online, rewards, next_obs, disc)
    np.testing.assert_allclose(y2.numpy(), [1 + g * 2, 2.0, -0.5 + g**3 * 0.5], rtol=1e-6)


def test_loss_is_mean_squared_td_error_of_eq_11():
    torch.manual_seed(0)
    agent = DQNAgent(_tiny_cfg())
    b = _batch()
    loss, info = agent.loss(b)
    q = agent.q(b.obs).gather(1, b.actions[:, None]).squeeze(1)
    with torch.no_grad():
        y = b.rewards + b.discounts * agent.q_target(b.next_obs).max(1).values
    assert float(loss.detach()) == pytest.approx(float(((q - y) ** 2).mean().detach()), rel=1e-6)
    assert info["td_loss"] == pytest.approx(float(loss.detach()), rel=1e-6)


def test_large_margin_loss_zero_when_demo_action_wins_by_margin():
    q = torch.tensor([[0.0, 1.0, 0.0], [0.0, 0.5, 0.3]])
    a = torch.tensor([1, 1])
    # row 0: 1 beats others by 1 >= 0.8 -> 0; row 1: max(0.8, 0.5, 1.1) - 0.5 = 0.6
    assert float(large_margin_loss(q, a, 0.8)) == pytest.approx(0.3)


def test_nstep_from_episodes_terminal_and_truncated():
    g = 0.5
    obs = np.arange(5, dtype=np.float32)[:, None].repeat(7, 1)
    nxt = obs + 1
    r = np.array([1.0, 2.0, 3.0, 10.0, 20.0])
    term = np.array([False, False, True, False, False])  # ep 0 terminates, ep 1 is truncated
    ep = np.array([0, 0, 0, 1, 1])
    _, _, rn, nn_, d = nstep_from_episodes(obs, np.zeros(5, int), r, nxt, term, ep, g, 2)
    np.testing.assert_allclose(rn, [1 + 0.5 * 2, 2 + 0.5 * 3, 3, 10 + 0.5 * 20, 20])
    np.testing.assert_allclose(d, [0.25, 0.0, 0.0, 0.25, 0.5])
    np.testing.assert_allclose(nn_[:, 0], [2, 3, 3, 5, 5])


def test_nstep_collector_matches_offline_nstep():
    rng = np.random.default_rng(0)
    n_env, n, g, t_len = 3, 3, 0.9, 12
    col = NStepCollector(n_env, n, g)
    obs_seq = rng.normal(size=(t_len + 1, n_env, 7)).astype(np.float32)
    r = rng.normal(size=(t_len, n_env))
    term = np.zeros((t_len, n_env), bool)
    trunc = np.zeros((t_len, n_env), bool)
    term[4, 0] = True
    trunc[7, 1] = True
    got = []
    for t in range(t_len):
        done = term[t] | trunc[t]
        tr = col.step(
            obs_seq[t],
            np.zeros(n_env, int),
            r[t],
            obs_seq[t + 1],
            term[t],
            trunc[t],
            obs_seq[t + 1] if done.any() else None,
        )
        got += [
            tuple(round(float(x), 5) for x in (o[0], rr, dd))
            for o, rr, dd in zip(tr[0], tr[2], tr[4], strict=True)
        ]
    # offline reference per env: split into episodes at done steps; the tail is still open
    want = []
    for e in range(n_env):
        starts = 0
        ends = [t for t in range(t_len) if term[t, e] or trunc[t, e]]
        for end in ends:
            seg = range(starts, end + 1)
            o = obs_seq[list(seg), e]
            _, _, rn, _, d = nstep_from_episodes(
                o,
                np.zeros(len(o), int),
                r[list(seg), e],
                o,
                term[list(seg), e],
                np.zeros(len(o)),
                g,
                n,
            )
            want += [
                tuple(round(float(x), 5) for x in (oo[0], rr, dd))
                for oo, rr, dd in zip(o, rn, d, strict=True)
            ]
            starts = end + 1
        # open tail: only windows that are complete have been emitted
        for t in range(starts, t_len - n + 1):
            rn = sum(g**k * r[t + k, e] for k in range(n))
            want.append(tuple(round(float(x), 5) for x in (obs_seq[t, e, 0], rn, g**n)))
    assert sorted(got) == sorted(want)


def test_config_flags_and_presets():
    docs = field_docs()
    for name in ("lr", "gamma", "batch_demo", "target_period", "resume", "seed"):
        assert docs.get(name), name
    p = argparse.ArgumentParser()
    add_arguments(p)
    cfg = from_args(p.parse_args(["--preset", "paper-agent2", "--lr", "3e-4", "--double-dqn"]))
    assert cfg.batch_agent == 200 and cfg.batch_demo == 0 and cfg.lr == 3e-4 and cfg.double_dqn
    a1 = preset("paper-agent1")
    assert (a1.lr, a1.gamma, a1.batch_agent, a1.batch_demo, a1.target_period) == (
        1e-5,
        0.926,
        100,
        100,
        65,
    )
    assert a1.hidden == (300, 200, 300) and a1.optimizer == "rmsprop" and a1.epsilon0 == 0.6
    assert set(PRESETS) == {
        "paper-agent1",
        "paper-agent2",
        "best",
        "robust",
        "ocp",
        "ocp-dagger",
        "ocp-adapt",
    }
    # issue 32: from scratch, and every demonstration from the optimal-control teacher
    ocp = preset("ocp")
    assert ocp.init_policy == "" and ocp.demos == "" and ocp.controller == "mpc-fuel-reserve-state"
    assert ocp.controller_demo_episodes > 0 and ocp.layer and ocp.batch_demo > 0
    dagger = preset("ocp-dagger")  # its rounds label with the same teacher, no other source
    assert dagger.controller == "mpc-fuel-reserve-state" and dagger.demos == ""
    assert dagger.dagger_rounds > 0 and dagger.label_episodes > 0
    robust = preset("robust")
    assert robust.init_policy == "models/pd_dqn_best.pt" and robust.dispersions == "standard"
    assert robust.recovery_demo_episodes == robust.controller_demo_episodes == 1000
    cfg = from_args(p.parse_args(["--hidden", "16,8"]))
    assert cfg.hidden == (16, 8)
