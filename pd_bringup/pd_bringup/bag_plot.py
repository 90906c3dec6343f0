"""The flight path and the OCP plan of a recorded bag, drawn to a PNG (`scripts/bag_to_png.py`).

    scripts/bag_to_png.py bags/run1 out/landing.png
    scripts/bag_to_png.py bags/run1 out/landing.png --path-index -2   # the flight before

Reads the bag with `rosbags` (no ROS context): the nav_msgs/Path messages of `lander/path` (the
simulator publishes the episode so far while it flies and the whole episode when it ends; the
last message is the last episode) and `ocp/plan` (the last successful OCP answer), in any
namespace. Draws three views in the landing-site frame (downrange-altitude,
crossrange-altitude, and from above) with pd_core.plots' matplotlib set-up (Agg backend).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from pd_bringup.bag import BagError, deserialize_all, read_bag
from pd_core.plots import _plt
from pd_ros_common import names


def _topic(topics: list[str], relative: str) -> str | None:
    """The bag topic that is `relative` in some namespace (the root one first)."""
    matches = sorted(t for t in topics if t == "/" + relative or t.endswith("/" + relative))
    return matches[0] if matches else None


def positions(path_msg: Any) -> np.ndarray:
    """(N, 3) positions of a nav_msgs/Path (decoded by rosbags)."""
    p = [(s.pose.position.x, s.pose.position.y, s.pose.position.z) for s in path_msg.poses]
    return np.asarray(p, dtype=float).reshape(-1, 3)


def paths_of(bag: str | Path, path_index: int = -1) -> tuple[np.ndarray, np.ndarray | None, str]:
    """(flight positions, plan positions or None, flight topic) of a bag; BagError if the bag
    has no flight path."""
    topics = list(read_bag(bag, topics=[]).topics)
    flight_topic = _topic(topics, names.PATH_TOPIC)
    plan_topic = _topic(topics, names.PLAN_TOPIC)
    wanted = [t for t in (flight_topic, plan_topic) if t]
    msgs = deserialize_all(bag, wanted) if wanted else {}
    flights = [m for m in msgs.get(flight_topic, []) if m.poses]
    if not flights:
        raise BagError(f"{bag}: no {names.PATH_TOPIC} messages (record it: pd_record's default)")
    try:
        flight = positions(flights[path_index])
    except IndexError:
        raise BagError(f"{bag}: --path-index {path_index}, but {len(flights)} paths") from None
    plans = [m for m in msgs.get(plan_topic, []) if m.poses]
    return flight, positions(plans[-1]) if plans else None, flight_topic or ""


def render(
    bag: str | Path, out: str | Path, path_index: int = -1, title: str | None = None
) -> Path:
    """Draw the flight (and the last OCP plan) of `bag` to `out`; the PNG's path."""
    flight, plan, topic = paths_of(bag, path_index)
    plt = _plt()
    fig, ax = plt.subplots(1, 3, figsize=(14, 4.8))
    views = [
        (0, 2, "downrange x (m)", "altitude z (m)"),
        (1, 2, "crossrange y (m)", "altitude z (m)"),
        (0, 1, "downrange x (m)", "crossrange y (m)"),
    ]
    for a, (i, j, xlabel, ylabel) in zip(ax, views, strict=True):
        a.plot(flight[:, i], flight[:, j], "-", lw=1.6, label=f"flight ({topic})")
        a.plot(flight[0, i], flight[0, j], "o", ms=5, color="C0")
        a.plot(flight[-1, i], flight[-1, j], "x", ms=7, color="C0")
        if plan is not None:
            a.plot(plan[:, i], plan[:, j], "--", lw=1.2, color="C1", label="last OCP plan")
        a.plot(0.0, 0.0, "k^", ms=7, label="landing site")
        a.axhline(0.0, color="grey", lw=0.7)
        a.axvline(0.0, color="grey", lw=0.7)
        a.set_xlabel(xlabel)
        a.set_ylabel(ylabel)
        a.legend(fontsize=7)
    end = flight[-1]
    fig.suptitle(
        title
        or f"{Path(bag).name}: {len(flight)} poses, touchdown at x = {end[0]:.2f} m, "
        f"y = {end[1]:.2f} m"
    )
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return Path(out)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="bag_to_png.py", description=__doc__.split("\n\n")[0] if __doc__ else None
    )
    p.add_argument("bag", type=Path, help="bag folder (pd_record's output)")
    p.add_argument("out", type=Path, help="PNG to write")
    p.add_argument(
        "--path-index",
        type=int,
        default=-1,
        help="which lander/path message to draw (default -1: the last one)",
    )
    p.add_argument("--title", default=None, help="figure title (default: the bag and touchdown)")
    args = p.parse_args(argv)
    try:
        out = render(args.bag, args.out, args.path_index, args.title)
    except (BagError, OSError) as exc:
        print(f"bag_to_png: {exc}", file=sys.stderr)
        return 2
    print(f"bag_to_png: wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
