"""Training speed on this machine, side by side in one run.

    python bench/train_speed.py [--threads 1] [--seconds 3] [--ratio-check 4000]

1. The paper's gradient update (7-300-200-300-147 tanh, RMSProp, 100 agent + 100 demonstration
   samples, Table 2): our `DQNAgent.update` fed by our replay memories, beside a minimal plain-torch
   loop of the same update on fixed tensors, with the GFLOP/s each achieves against a large matmul.
   Then updates/s on every device present, each beside the plain-torch loop on that device: the
   CPU (numpy replay, as `pd-train --device cpu`; and the device code path, eager), and where torch
   sees a GPU, cuda eager and cuda graph (`pd-train --device cuda`: replay memories on the GPU, the
   whole update one CUDA graph; the plain loop captured the same way).
   1c. The paper's update for K in {1, 8, 32, 128} updates per block: the plain loop, the
   graph path of 1 and the device loop (`pd-train --loop device`), one and several agents
   together, on every device present; then the whole device loop with its envs.
   1b. The recipe's update (`ocp-dagger`) beside the same update as the plain per-tensor loop
   it was up to 2f59083 (module calls, per-tensor Adam and average), blocks interleaved,
   with the ratio and a check that both give the same weights to the bit.
2. What one env step of the paper's loop (`pd-train --preset paper-agent1`, one env) costs besides
   the update: epsilon-greedy action, env step, n-step collector, replay insert, minibatch sampling,
   so the per-step cost of any `--updates-per-step` ratio can be read off.
3. Env throughput, other presets' updates/s, and `Policy.act` latency.
4. With --ratio-check N (minutes of CPU): the paper's ratio, one update per env transition, flown
   with 1 env and with 16 envs (--updates-per-step 16), paper-agent2, N updates, seeds 1 and 2:
   wall time, and the greedy evaluation of each after N/2 and N updates on the same episodes.
"""

from __future__ import annotations

import argparse
import copy
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from pd_core.dqn.agent import DQNAgent, concat_samples
from pd_core.dqn.config import TrainConfig, preset
from pd_core.dqn.device import WARMUP_STEPS, DeviceReplay, DeviceUpdate
from pd_core.dqn.device_loop import DeviceLoop
from pd_core.dqn.network import QNetwork
from pd_core.dqn.replay import DemoMemory, NStepCollector, ReplayMemory
from pd_core.dqn.train import Trainer
from pd_core.vector_env import make_vector_env


def _timed(fn, seconds: float) -> tuple[int, float]:
    fn()  # warm-up
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        fn()
        n += 1
    return n, time.perf_counter() - t0


def _per_s(fn, seconds: float) -> float:
    n, dt = _timed(fn, seconds)
    return n / dt


def update_flops(hidden: tuple[int, ...], batch: int, n_in: int = 7, n_out: int = 147) -> float:
    """FLOPs of one DQN update: forward + backward (2x forward) of the online network on the
    batch, plus the target network's forward on the next states (multiply-add = 2 FLOPs)."""
    widths = (n_in, *hidden, n_out)
    fwd = 2.0 * batch * sum(a * b for a, b in zip(widths[:-1], widths[1:], strict=True))
    return 3.0 * fwd + fwd


def matmul_gflops(seconds: float, n: int = 2048) -> float:
    a, b = torch.randn(n, n), torch.randn(n, n)
    return _per_s(lambda: a @ b, seconds) * 2.0 * n**3 / 1e9


def _memories(rng: np.random.Generator) -> tuple[ReplayMemory, DemoMemory]:
    mem, obs = ReplayMemory(20_000), rng.normal(size=(20_000, 7)).astype(np.float32)
    mem.add(obs, rng.integers(0, 147, 20_000), rng.normal(size=20_000), obs, np.full(20_000, 0.9))
    demo = DemoMemory.fill(
        obs[:5000], rng.integers(0, 147, 5000), np.zeros(5000), obs[:5000], np.zeros(5000)
    )
    return mem, demo


def ours_updates_per_s(name: str, seconds: float, **kw) -> float:
    """`DQNAgent.update` on minibatches sampled from our replay memories, as `pd-train` does."""
    cfg = replace(preset(name), **kw)
    agent = DQNAgent(cfg)
    rng = np.random.default_rng(0)
    mem, demo = _memories(rng)

    def upd() -> None:
        b = mem.sample(cfg.batch_agent, rng)
        if cfg.batch_demo:
            b = concat_samples(b, demo.sample(cfg.batch_demo, rng))
        agent.update(b)

    return _per_s(upd, seconds)


def minimal_updates_per_s(seconds: float, batch: int = 200) -> float:
    """The same update in plain torch on fixed tensors: the floor our loop is measured against."""
    torch.manual_seed(0)
    q = QNetwork()
    qt = copy.deepcopy(q)
    opt = torch.optim.RMSprop(q.parameters(), lr=1e-5)
    obs, nobs = torch.randn(batch, 7), torch.randn(batch, 7)
    a, r, d = torch.randint(0, 147, (batch,)), torch.randn(batch), torch.rand(batch)

    def upd() -> None:
        qa = q(obs).gather(1, a[:, None]).squeeze(1)
        with torch.no_grad():
            tgt = r + d * qt(nobs).max(1).values
        loss = F.mse_loss(qa, tgt)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    return _per_s(upd, seconds)


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def _per_s_on(fn, seconds: float, device: torch.device, warmup: int = 1) -> float:
    """Calls per second of `fn` on `device`: cuda launches are asynchronous, so the clock is
    read after a synchronise at both ends (the queue in between keeps the GPU busy)."""
    for _ in range(warmup):
        fn()
    _sync(device)
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        for _ in range(10):
            fn()
        n += 10
    _sync(device)
    return n / (time.perf_counter() - t0)


def device_path_updates_per_s(device: torch.device, graph: bool, seconds: float) -> float:
    """`pd-train`'s device path (`DeviceUpdate`): replay memories on `device`, indices drawn
    there, the step eager or one CUDA graph; the paper's update (paper-agent1)."""
    cfg = preset("paper-agent1")
    torch.manual_seed(0)
    agent = DQNAgent(cfg, device=device, capturable=graph)
    mem, demo = _memories(np.random.default_rng(0))
    gen = torch.Generator(device=device)
    gen.manual_seed(0)
    upd = DeviceUpdate(
        agent,
        DeviceReplay.from_memory(mem, device),
        DeviceReplay.from_memory(demo, device),
        generator=gen,
        graph=graph,
    )
    return _per_s_on(upd, seconds, device, warmup=WARMUP_STEPS + 2)


def plain_updates_per_s(device: torch.device, graph: bool, seconds: float, batch: int = 200):
    """The plain-torch loop of `minimal_updates_per_s` on `device`, eager or captured whole in a
    CUDA graph (static tensors, capturable RMSprop)."""
    torch.manual_seed(0)
    q = QNetwork().to(device)
    qt = copy.deepcopy(q)
    opt = torch.optim.RMSprop(q.parameters(), lr=1e-5, capturable=graph)
    obs, nobs = torch.randn(batch, 7, device=device), torch.randn(batch, 7, device=device)
    a = torch.randint(0, 147, (batch,), device=device)
    r, d = torch.randn(batch, device=device), torch.rand(batch, device=device)

    def upd() -> None:
        qa = q(obs).gather(1, a[:, None]).squeeze(1)
        with torch.no_grad():
            tgt = r + d * qt(nobs).max(1).values
        loss = F.mse_loss(qa, tgt)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    if not graph:
        return _per_s_on(upd, seconds, device)
    side = torch.cuda.Stream()
    side.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(side):
        for _ in range(WARMUP_STEPS):
            upd()
    torch.cuda.current_stream().wait_stream(side)
    g = torch.cuda.CUDAGraph()
    with torch.cuda.graph(g):
        upd()
    return _per_s_on(g.replay, seconds, device)


def device_report(seconds: float, numpy_ups: float, plain_cpu_ups: float) -> None:
    """Part 1, continued: updates/s on every device here, beside the plain loop there."""
    rows = [
        ("cpu", "numpy replay (--device cpu)", numpy_ups, plain_cpu_ups),
        (
            "cpu",
            "device path, eager",
            device_path_updates_per_s(torch.device("cpu"), False, seconds),
            plain_cpu_ups,
        ),
    ]
    if torch.cuda.is_available():
        cuda = torch.device("cuda")
        for graph, mode in ((False, "eager"), (True, "CUDA graph (--device cuda)")):
            rows.append(
                (
                    f"cuda ({torch.cuda.get_device_name(cuda)})",
                    mode,
                    device_path_updates_per_s(cuda, graph, seconds),
                    plain_updates_per_s(cuda, graph, seconds),
                )
            )
    else:
        rows.append(("cuda", "none here: torch sees no GPU", float("nan"), float("nan")))
    print("   updates/s on every device here, beside the plain-torch loop on the same device")
    print(f"   {'device':34s} {'mode':28s} {'pd-train':>9s} {'plain':>9s} {'ratio':>6s}")
    for dev, mode, ours, plain in rows:
        print(f"   {dev:34s} {mode:28s} {ours:9.1f} {plain:9.1f} {ours / plain:6.2f}")
    best = max((r for r in rows if r[2] == r[2]), key=lambda r: r[2])
    print(f"   fastest: {best[0]}, {best[1]}: {best[2] / numpy_ups:.1f}x the CPU's numpy path")


def _device_loop(device: torch.device, agents: int, k: int, **kw) -> DeviceLoop:
    """A device loop of `agents` paper-agent1 seeds, K = `k` updates per block, on `device`."""
    cfg = preset(
        "paper-agent1", num_envs=16, updates_per_step=float(k), learning_starts=1000,
        eval_every_s=0.0, progress=False, device=device.type, **kw,
    )  # fmt: skip
    cfgs = [replace(cfg, seed=s) for s in range(1, agents + 1)]
    d = Path(tempfile.mkdtemp(prefix="pd_train_speed_"))
    return DeviceLoop(cfgs, [d / str(c.seed) for c in cfgs], quiet=True, capacity=100_000)


def block_updates_per_s(device: torch.device, agents: int, k: int, seconds: float) -> float:
    """Updates/s of each agent in the device loop's update block alone (K updates, one graph
    on cuda), memories full of random rows."""
    loop = _device_loop(device, agents, k)
    loop.store.copy_(torch.randn_like(loop.store))
    loop.store[:, 7].copy_(torch.randint(0, 147, (loop.store.shape[0],), device=device))
    for agent in loop.agents:
        agent.replay_size = loop.capacity
    owed = [k] * agents
    return k * _per_s_on(lambda: loop.update_block(owed), seconds, device, warmup=4)


def block_profile(device: torch.device, agents: int, k: int = 16) -> str:
    """Kernels per update and GPU time per update of the device loop's block (torch.profiler
    over 10 blocks after warm-up): where the time of an update goes."""
    from torch.profiler import ProfilerActivity, profile  # the profiler: only when asked

    loop = _device_loop(device, agents, k)
    for agent in loop.agents:
        agent.replay_size = loop.capacity
    owed = [k] * agents
    for _ in range(4):
        loop.update_block(owed)
    _sync(device)
    with profile(activities=[ProfilerActivity.CUDA]) as prof:
        for _ in range(10):
            loop.update_block(owed)
        _sync(device)
    events = [e for e in prof.events() if e.device_type.name == "CUDA"]
    gpu_us = sum(e.device_time for e in events)
    n = 10 * k
    return f"{len(events) / n:.1f} kernels and {gpu_us / n:.1f} us of GPU time per update"


def loop_updates_per_s(device: torch.device, agents: int, seconds: float) -> float:
    """Updates/s of each agent in the whole device loop (act, env step, inserts, a block of
    16 updates per step of 16 envs), after its first 1000 transitions."""
    loop = _device_loop(device, agents, 16)
    pending = [0] * agents
    while loop.agents[0].updates < 2000:
        pending = loop.iterate(pending)
    _sync(device)
    u0, t0 = loop.agents[0].updates, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        pending = loop.iterate(pending)
    _sync(device)
    return (loop.agents[0].updates - u0) / (time.perf_counter() - t0)


def device_loop_report(seconds: float, agents: tuple[int, ...] = (1, 4), cpu: bool = True) -> None:
    """Part 1c: the paper's update in the plain torch loop, today's graph path (`DeviceUpdate`)
    and the device loop, for K in {1, 8, 32, 128} updates per block, on every device here
    (without `cpu`, on the GPU alone)."""
    devices = [torch.device("cpu")] if cpu else []
    if torch.cuda.is_available():
        devices.append(torch.device("cuda"))
    print("1c. The paper's update: plain torch, the graph path and the device loop (updates/s")
    print("    of one agent; with A agents together, of each; total = A x that)")
    head = f"   {'device':28s} {'K':>4s} {'plain':>8s} {'graph path':>10s}"
    head += "".join(f" {f'loop A={a}':>10s}" for a in agents) + f" {'loop/graph':>10s}"
    print(head)
    for dev in devices:
        name = dev.type if dev.type == "cpu" else f"cuda ({torch.cuda.get_device_name(dev)})"
        graph = dev.type == "cuda"
        plain = plain_updates_per_s(dev, graph, seconds)
        path = device_path_updates_per_s(dev, graph, seconds)
        for k in (1, 8, 32, 128):
            ups = [block_updates_per_s(dev, a, k, seconds) for a in agents]
            row = f"   {name:28s} {k:4d} {plain:8.0f} {path:10.0f}"
            print(row + "".join(f" {u:10.0f}" for u in ups) + f" {ups[0] / path:10.2f}")
        if dev.type == "cuda":
            for a in agents:
                try:
                    print(f"   {name:28s} block of 16, A={a}: {block_profile(dev, a)}")
                except Exception as exc:  # noqa: BLE001 - a profiler failure is no bench failure
                    print(f"   {name:28s} block of 16, A={a}: no profile ({exc})")
        whole = [loop_updates_per_s(dev, a, seconds) for a in agents]
        row = f"   {name:28s} {'env':>4s} {'':8s} {'':10s}"
        print(row + "".join(f" {u:10.0f}" for u in whole) + "   (whole loop, 16 envs, K 16)")


def ratio_check(
    updates: int, seeds: tuple[int, ...] = (1, 2), episodes: int = 200, lr: float = 0.0
) -> None:
    """Part 4: the paper's ratio with 1 env and with 16 envs, same seed and update count."""
    lr = lr or preset("paper-agent2").lr
    print(
        f"4. The paper's ratio (1 update per env transition), paper-agent2 (lr {lr:g}), "
        f"{updates} updates, greedy evaluation on the same {episodes} episodes (seed 900000)"
    )
    cols = ("success_rate", "pos_median", "kvel_min", "fuel_median", "mean_return")
    print(f"   {'seed':>4s} {'envs':>4s} {'updates':>7s} {'wall s':>7s} " + " ".join(
        f"{c:>12s}" for c in cols
    ))  # fmt: skip
    with tempfile.TemporaryDirectory() as d:
        for seed in seeds:
            for n in (1, 16):
                cfg = preset(
                    "paper-agent2", seed=seed, num_envs=n, updates_per_step=float(n),
                    max_updates=updates // 2, eval_every_s=0.0, checkpoint_every_s=1e9, lr=lr,
                    progress=False, device="cpu", run_dir=f"{d}/s{seed}n{n}",
                )  # fmt: skip
                tr, wall = Trainer(cfg, quiet=True), 0.0
                for stop in (updates // 2, updates):
                    if stop > cfg.max_updates:
                        tr = Trainer.resume(cfg.run_dir, {"max_updates": stop})
                        tr.quiet = True
                    t0 = time.perf_counter()
                    tr.run()
                    wall += time.perf_counter() - t0
                    ev = tr.evaluate(episodes, seed=900_000)
                    vals = " ".join(f"{ev[c]:12.3f}" for c in cols)
                    print(f"   {seed:4d} {n:4d} {tr.agent.updates:7d} {wall:7.1f} {vals}")


def loop_costs_us(seconds: float) -> dict[str, float]:
    """Microseconds per call of each piece of the paper preset's loop (one env)."""
    cfg = preset("paper-agent1")
    agent = DQNAgent(cfg)
    rng = np.random.default_rng(0)
    mem, demo = _memories(rng)
    env = make_vector_env(1)
    obs, _ = env.reset(seed=0)
    col = NStepCollector(1, cfg.n_step, cfg.gamma)
    acts = rng.integers(0, 147, size=(1,))
    out: dict[str, float] = {}

    def step() -> None:
        nonlocal obs
        nobs, r, term, trunc, info = env.step(acts)
        obs = nobs

    pieces = {
        "act (epsilon-greedy, 1 state, eps 0.3)": lambda: agent.act(obs, 0.3, rng),
        "env.step (vector env, 1 env)": step,
        "n-step collector": lambda: col.step(
            obs, acts, np.zeros(1), obs, np.zeros(1, bool), np.zeros(1, bool), None
        ),
        "replay add (1 transition)": lambda: mem.add(obs, acts, np.zeros(1), obs, np.ones(1)),
        "sample 100 + 100 demo": lambda: concat_samples(
            mem.sample(100, rng), demo.sample(100, rng)
        ),
    }
    for name, fn in pieces.items():
        n, dt = _timed(fn, seconds)
        out[name] = 1e6 * dt / n
    return out


def env_steps_per_s(num_envs: int, seconds: float) -> float:
    env = make_vector_env(num_envs)
    env.reset(seed=0)
    acts = np.random.default_rng(0).integers(0, 147, size=(64, num_envs))
    i = [0]

    def step() -> None:
        env.step(acts[i[0] % 64])
        i[0] += 1

    return _per_s(step, seconds) * num_envs


def per_tensor_agent(cfg: TrainConfig) -> DQNAgent:
    """An agent whose update runs as the plain per-tensor loop did up to 2f59083: module
    calls, torch's CPU default Adam (a Python loop over tensors), the parameter lists walked
    every update, one `lerp_` per parameter for the average (the same bits as ours)."""
    a = DQNAgent(cfg)
    for g in a.opt.param_groups:
        g["foreach"] = None

    def gradient_step(loss: torch.Tensor) -> None:
        a.opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(a.q.parameters(), a.cfg.grad_clip)
        a.opt.step()

    def average_step() -> None:
        with torch.no_grad():
            for w_avg, w in zip(a.q_avg.parameters(), a.q.parameters(), strict=True):
                w_avg.lerp_(w, 1.0 - a.cfg.weight_average)

    a.gradient_step, a.average_step = gradient_step, average_step
    for net in (a.q, a.q_target, a.q_avg):
        net.forward = lambda obs, net=net: net.net(net.inputs(obs))
    return a


def recipe_update_report(seconds: float, blocks: int = 40) -> None:
    """Part 1b: the recipe's update (`ocp-dagger`: 128 + 128 demonstrations, Adam, clip, weight
    average, near-pad inputs), ours against the per-tensor loop, blocks of 50 updates on the
    same batches interleaved (this machine's speed drifts), and the weights compared."""
    cfg = preset("ocp-dagger")
    rng = np.random.default_rng(0)
    _mem, demo = _memories(rng)
    batches = [demo.sample(cfg.batch_agent + cfg.batch_demo, rng) for _ in range(50)]
    torch.manual_seed(0)
    before_agent = per_tensor_agent(cfg)
    torch.manual_seed(0)
    agents = {"per-tensor loop (before)": before_agent, "pd-train (DQNAgent)": DQNAgent(cfg)}
    ms: dict[str, list[float]] = {k: [] for k in agents}
    t_end = time.perf_counter() + seconds * 4  # the first pass always runs
    while len(ms["pd-train (DQNAgent)"]) < blocks and time.perf_counter() < t_end:
        for name, agent in agents.items():
            t0 = time.perf_counter()
            for b in batches:
                agent.update(b)
                agent.average_step()
            ms[name].append(1e3 * (time.perf_counter() - t0) / len(batches))
    before, ours = (np.array(v) for v in ms.values())
    same = all(
        torch.equal(x, y)
        for x, y in zip(*(a.policy_net.state_dict().values() for a in agents.values()), strict=True)
    )
    print("1b. The recipe's update (ocp-dagger, batch 128 + 128, Adam, clip 10, weight average)")
    for name, v in ms.items():
        print(f"   {name:34s} {np.median(v):8.2f} ms median of {len(v)} blocks of 50")
    print(
        f"   ours / before, paired blocks: median {np.median(ours / before):.3f}, ours faster in "
        f"{int((ours < before).sum())} of {len(ours)}; the same weights to the bit: {same}"
    )


def paper_update_report(seconds: float) -> float:
    """Part 1; returns the update time in microseconds (ours)."""
    flops = update_flops(preset("paper-agent1").hidden, 200)
    peak = matmul_gflops(seconds)
    ours = ours_updates_per_s("paper-agent1", seconds)
    floor = minimal_updates_per_s(seconds)
    print("1. The paper's update (batch 100 + 100, 7-300-200-300-147 tanh, RMSProp)")
    print(f"   {'':34s} {'updates/s':>10s} {'GFLOP/s':>8s} {'of matmul':>10s}")
    for name, ups in (("pd-train (DQNAgent + replay)", ours), ("minimal plain-torch loop", floor)):
        g = ups * flops / 1e9
        print(f"   {name:34s} {ups:10.1f} {g:8.1f} {g / peak:9.0%}")
    print(f"   {'2048x2048 matmul':34s} {'':10s} {peak:8.1f} {1:9.0%}")
    print(f"   ours / minimal: {ours / floor:.2f}; {flops / 1e6:.0f} MFLOP per update")
    device_report(seconds, ours, floor)
    return 1e6 / ours


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    ap.add_argument("--seconds", type=float, default=3.0, help="seconds per figure (default 3)")
    ap.add_argument(
        "--ratio-check",
        type=int,
        default=0,
        metavar="UPDATES",
        help="also part 4: 1 env against 16 envs at the paper's ratio, this many updates "
        "(a few minutes of CPU at 4000; default 0: skip)",
    )
    ap.add_argument("--ratio-lr", type=float, default=0.0, help="part 4's lr (default: Table 2)")
    ap.add_argument("--only-updates", action="store_true", help="part 1 only (and part 4)")
    ap.add_argument("--device-loop", action="store_true", help="part 1c only")
    ap.add_argument("--gpu-only", action="store_true", help="part 1c on the GPU alone")
    ap.add_argument(
        "--agents", type=int, nargs="+", default=[1, 4], help="part 1c's agents together"
    )
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    print(f"torch threads: {a.threads}")
    if a.device_loop:
        device_loop_report(a.seconds, tuple(a.agents), cpu=not a.gpu_only)
        return
    upd_us = paper_update_report(a.seconds)
    recipe_update_report(a.seconds)
    device_loop_report(a.seconds, tuple(a.agents))
    if a.only_updates:
        if a.ratio_check:
            ratio_check(a.ratio_check, lr=a.ratio_lr)
        return
    costs = loop_costs_us(a.seconds)
    print("2. One env step of the paper's loop besides the update (us per call)")
    for name, us in costs.items():
        print(f"   {name:42s} {us:9.1f}")
    per_step = sum(v for k, v in costs.items() if not k.startswith("sample"))
    sample = costs["sample 100 + 100 demo"]
    print(f"   {'per env step without updates':42s} {per_step:9.1f}")
    for ratio in (1.0, 0.25, 0.125):
        total = per_step + ratio * (upd_us + sample)
        share = ratio * (upd_us + sample) / total
        print(
            f"   --updates-per-step {ratio:<5}: {total:8.0f} us per env step "
            f"({1e6 / total:6.0f} steps/s), updates {share:.0%} of it"
        )
    print("3. Other figures")
    for n in (1, 32, 4096):
        print(f"   env steps/s, vector env, {n:5d} envs: {env_steps_per_s(n, a.seconds):12.0f}")
    for name, kw in (("paper-agent2", {}), ("best", {})):
        cfg = replace(preset(name), **kw)
        ups = ours_updates_per_s(name, a.seconds, **kw)
        print(f"   updates/s, {name:12s} batch {cfg.batch_agent}+{cfg.batch_demo}: {ups:8.1f}")
    print("   one decision of a policy file behind its runtime layer: bench/runtime_speed.py")
    if a.ratio_check:
        ratio_check(a.ratio_check, lr=a.ratio_lr)


if __name__ == "__main__":
    main()
