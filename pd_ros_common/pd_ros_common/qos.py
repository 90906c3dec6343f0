"""QoS profiles of the stack, in one place.

State and commands (RELIABLE, VOLATILE, KEEP_LAST): every message counts and nobody needs old
ones, so any RELIABLE or BEST_EFFORT VOLATILE reader matches. Depth is not part of QoS matching,
but it decides what is lost:
- publishers keep `HISTORY_DEPTH` messages (more than a 750-step episode): a KEEP_LAST writer drops
  its oldest sample for every reader once its history is full, acknowledged or not;
- subscriptions keep as many, so the worst burst the stack itself makes (a lockstep run, a
  replay at full speed, a publisher's whole history after a stall) waits in the queue instead of
  being dropped; what is still dropped is counted (message-lost events and step gaps).
Episode results are TRANSIENT_LOCAL: a late subscriber still gets the last ones; so are the
paths (lander/path, ocp/plan: depth 1, a viewer started late still draws the last one). A path
is a latest-value topic (`keeps_latest_only`): each message holds the whole path so far, and a
newer one may replace one not yet delivered, by design; a recorder counts those as superseded,
not lost.
/diagnostics is RELIABLE, VOLATILE, depth 10 (as diagnostic_updater). /clock is RELIABLE, VOLATILE,
depth 10: rclpy's own /clock subscription (BEST_EFFORT, depth 1) and any RELIABLE one match it.
Services keep `SERVICE_DEPTH` requests and responses (the default 10 loses most of a burst).
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

HISTORY_DEPTH = 1000
SERVICE_DEPTH = 200


def _profile(depth: int, durability: DurabilityPolicy = DurabilityPolicy.VOLATILE) -> QoSProfile:
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=durability,
    )


def keeps_latest_only(profile: QoSProfile) -> bool:
    """True for a latest-value profile (KEEP_LAST, depth 1): its writer replaces a sample not
    yet delivered by the next one, so a skipped sequence number is superseded, not lost."""
    return profile.history == HistoryPolicy.KEEP_LAST and profile.depth == 1


LOOP_PUB_QOS = _profile(HISTORY_DEPTH)  # /lander/state, /lander/thrust_cmd publishers
LOOP_SUB_QOS = _profile(HISTORY_DEPTH)  # their subscriptions (nodes, recorder, probes)
EPISODE_QOS = _profile(10, DurabilityPolicy.TRANSIENT_LOCAL)  # /lander/episode
PATH_QOS = _profile(1, DurabilityPolicy.TRANSIENT_LOCAL)  # lander/path, ocp/plan
DIAGNOSTICS_QOS = _profile(10)  # /diagnostics
CLOCK_QOS = _profile(10)  # /clock
SERVICE_QOS = _profile(SERVICE_DEPTH)  # /sim/reset, /ocp/compute_trajectory (server and client)
