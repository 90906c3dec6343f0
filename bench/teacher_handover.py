"""How much of an MPC teacher's flight its ZEM/ZEV fallback flies, behind a runtime layer.

    python bench/teacher_handover.py [--episodes 50] [--seed 0] [--dispersions ""] SPEC ...

Each SPEC is a `pd-eval` spec of an MPC controller behind a layer
(`layer:controller:NAME`, `set:K=V:layer:controller:NAME`). Prints, per spec, the share of
the teacher's steps flown by its fallback (the hand-over near the pad, and every step after a
failed re-plan), the warm re-plans that needed the full thrust limits, the layer's changes and
the success rate (issue 68: "it does not hand over to ZEM/ZEV where it does not need to").
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from pd_core.episodes import rollout  # noqa: E402
from pd_core.runtime.build import build  # noqa: E402
from pd_core.runtime.layer import Runtime  # noqa: E402
from pd_core.teachers.mpc import MPCController  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("specs", nargs="+")
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--dispersions", default="")
    a = ap.parse_args()
    for spec in a.specs:
        built = build(spec)
        rt, label = built.actor, built.label
        if not isinstance(rt, Runtime) or not isinstance(rt.actor, MPCController):
            raise SystemExit(f"{spec}: not an MPC controller behind a runtime layer")
        ro = rollout(rt, a.episodes, a.seed, dispersions=a.dispersions)
        st = rt.actor.stats
        steps = int(np.sum(ro.steps))
        print(
            f"{label}: fallback {st.fallback_steps / steps:.1%} of {steps} steps, "
            f"full-limit re-plans {st.full_limits} of {len(st.warm)}, "
            f"layer changed {rt.changed / steps:.1%}, landed {ro.landed.mean():.1%}"
        )


if __name__ == "__main__":
    main()
