"""A digest of every decision a policy file makes over a campaign: does a change to the runtime
layer leave what shipped files fly unchanged, to the bit?

    python bench/decision_digest.py [--episodes 64] [--seed 4400000] [--dispersions broad]
        [SPEC ...]

Flies each agent (a `pd-eval` spec: a policy file, `layer:controller:NAME`, `set:K=V:SPEC`;
default: every policy file in models/, each behind its own pinned runtime layer) on
`--episodes` episodes of each scenario (episode i on env seed seed + i, `Runtime.step_rows` on
all landers still flying, as `pd_core.episodes.rollout` does) and prints the
SHA-256 of every step's record: the action flown, the action proposed, the source, the
identified delay, the thrust fraction counted on, whether the navigation filter was engaged, and
the true states after the step. Run it before and after a change; equal digests mean equal
flights (for the code before a change: `git archive` it and put its `pd_core` first on
PYTHONPATH). A `set:` spec changes runtime settings, to see that a digest does move when the
layer does.
"""

from __future__ import annotations

import argparse
import hashlib
import os
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from pd_core.dispersions import load_scenarios  # noqa: E402
from pd_core.runtime.build import build  # noqa: E402
from pd_core.runtime.layer import Runtime  # noqa: E402
from pd_core.vector_env import make_vector_env  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def digest(rt: Runtime, scenarios: list, episodes: int, seed: int) -> tuple[str, int]:
    """(SHA-256 hex of every decision and true state, decisions made)."""
    h = hashlib.sha256()
    steps = 0
    for d in scenarios:
        env = make_vector_env(episodes, autoreset=False, dispersions=d)
        _, info = env.reset(seed=seed)
        rt.begin_episodes(episodes)
        actions = np.zeros(episodes, dtype=np.int64)
        active = env.active
        while active.any():
            rows = np.flatnonzero(active)
            got, dec = rt.step_rows(info["observed_state"][active], rows)
            for a in (got, dec.proposed, dec.source, dec.delay_steps, dec.thrust_gain_bound,
                      dec.nav_filter_engaged):  # fmt: skip
                h.update(np.ascontiguousarray(a).tobytes())
            actions[active] = got
            _, _, _, _, info = env.step(actions)
            h.update(info["state"][active].tobytes())
            steps += len(rows)
            active = info["active"]
    return h.hexdigest(), steps


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("specs", nargs="*", help="agents (default: every models/*.pt)")
    ap.add_argument("--episodes", type=int, default=64, help="per scenario")
    ap.add_argument("--seed", type=int, default=4_400_000)
    ap.add_argument("--dispersions", default="broad")
    a = ap.parse_args(argv)
    specs = a.specs or [str(p) for p in sorted((ROOT / "models").glob("*.pt"))]
    scenarios = load_scenarios(a.dispersions)
    for spec in specs:
        rt = build(spec).actor
        if not isinstance(rt, Runtime):
            raise SystemExit(f"{spec}: not behind a runtime layer (no decisions to digest)")
        hexd, steps = digest(rt, scenarios, a.episodes, a.seed)
        name = Path(spec).name if Path(spec).is_file() else spec
        print(f"{hexd}  {name}  {steps} decisions, {len(scenarios)} scenarios", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
