"""pd_ocp_node: serves ocp/compute_trajectory (pd_interfaces/srv/ComputeTrajectory).

The request callback runs on a worker thread of a MultiThreadedExecutor in a
ReentrantCallbackGroup, and the solve itself (`pd_core.ocp.solve`, which never raises) runs in a
solver process (a one-worker spawn-context process pool), so neither the solver's CPU time nor its
hold on the GIL keeps the node from answering parameter queries and other requests while it works;
a solver process that crashes or overruns its time limit is replaced and the request answered
with success=false. At most `max_pending` requests are in the node at once (one
solving, the rest waiting their turn); more are answered at once with success=false ("busy"), so
executor threads are always left for parameter services. Bad requests (NaN/inf, mass <= dry mass,
altitude <= 0, absurd magnitudes, unknown method/objective) and solver failures or timeouts get
success=false with the reason; nothing a request holds can kill the node.

Each successful answer is also published on ocp/plan (nav_msgs/Path of the planned positions, frame
landing_site, TRANSIENT_LOCAL: a viewer started later still draws the last plan; pose k stamped
the node's time now plus the plan's state time k). /diagnostics (1 Hz): solve times, requests
pending, busy and failed answers (levels: pd_ros_common.diagnostics).

A managed (lifecycle) node: configure starts the solver process, activate lets requests through;
unconfigured or inactive, every request is answered success=false ("refused: pd_ocp_node is
inactive"), while parameters and /diagnostics keep answering. cleanup stops the solver process.
`autostart` (default true) configures and activates it at start-up.

Parameters are listed in PARAMETERS below (defaults in pd_bringup/config/ocp.yaml); method,
objective, control_points and timeout_s may be changed at run time (validated) and apply to the
next request that leaves the field empty or zero.
"""

from __future__ import annotations

import math
import multiprocessing
import signal
import sys
import threading
import time
from collections import deque
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from concurrent.futures.process import BrokenProcessPool
from typing import Any

import numpy as np
from nav_msgs.msg import Path
from rclpy.callback_groups import ReentrantCallbackGroup

from pd_core import ocp
from pd_core.config import OCP_CONTROL_POINTS
from pd_core.discretise import discretise
from pd_core.ocp import kernels
from pd_interfaces.srv import ComputeTrajectory
from pd_ros_common import diagnostics, names, params, qos
from pd_ros_common.convert import fill_ocp_response, from_vec3, plan_path_msg, vec3
from pd_ros_common.lifecycle import AUTOSTART, ManagedNode
from pd_ros_common.run import run_node

NODE_NAME = "pd_ocp_node"

PARAMETERS: dict[str, tuple[Any, str, bool]] = {
    "method": (
        ocp.DEFAULT_METHOD,
        f"Solver used when a request leaves `method` empty: one of {', '.join(ocp.METHODS)} "
        "('slsqp' is the paper's SciPy SLSQP; 'qp' is the fast structured solver).",
        False,
    ),
    "objective": (
        "energy",
        f"Objective when a request leaves `objective` empty: one of {', '.join(ocp.OBJECTIVES)} "
        "('energy' = Eq. 4).",
        False,
    ),
    "control_points": (
        OCP_CONTROL_POINTS,
        "Control points per axis when a request sends 0 (80 in Sec. 3.1).",
        False,
    ),
    "timeout_s": (
        60.0,
        "Solve time limit (s) when a request sends timeout 0; a solve past it fails with "
        "success=false and the reason.",
        False,
    ),
    "max_pending": (
        2,
        "Requests held at once (one solves, the others wait); further ones get success=false "
        "'busy' at once. Read at start-up (sizes the executor).",
        True,
    ),
    "autostart": (*AUTOSTART, True),
}
# The same checks at start-up and for `ros2 param set` (pd_ros_common.params).
CHECKS: dict[str, params.Check] = {
    "method": params.one_of(ocp.METHODS),
    "objective": params.one_of(ocp.OBJECTIVES),
    "control_points": params.at_least(2),
    "timeout_s": params.above(0.0),
    "max_pending": params.at_least(1),
}


def _warm_up() -> None:
    """Solver process initialiser. Unpickling it imports this module, and with it pd_core.ocp,
    in the solver process when the pool starts, not on the first request, and it loads the
    solvers' compiled kernels (`pd_core.ocp.kernels.warm_up`). Ctrl-C reaches the whole process
    group: the node stops its solver itself, so the solver ignores SIGINT."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    kernels.warm_up()


def _solver_pool() -> ProcessPoolExecutor:
    """A one-process spawn pool, its process started now with SIGINT blocked: the process
    inherits the mask, so a Ctrl-C to the whole process group during its start-up (before
    `_warm_up` ignores SIGINT) does not kill it with a traceback."""
    pool = ProcessPoolExecutor(
        max_workers=1, mp_context=multiprocessing.get_context("spawn"), initializer=_warm_up
    )
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        pool.submit(math.sqrt, 1.0)  # spawns the process (in this thread)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    return pool


# Extra wall time granted to a solver process beyond the solve's own time limit (transfer, a
# last iteration) before it is declared hung and replaced.
SOLVER_GRACE_S = 10.0


class OcpNode(ManagedNode):
    """Thin ROS adapter over `pd_core.ocp.solve`. configure starts the solver process (its
    kernels warmed up), activate lets requests through; otherwise they are answered
    success=false with the node's lifecycle state."""

    def __init__(self, **kwargs: Any) -> None:
        self._pool: ProcessPoolExecutor | None = None  # destroy_node works whatever fails
        super().__init__(NODE_NAME, **kwargs)
        p = params.declare(self, PARAMETERS, CHECKS)
        self.autostart = p["autostart"]
        self.max_pending = p["max_pending"]
        self._solve_lock = threading.Lock()  # one solve at a time: they are CPU-bound
        self._count_lock = threading.Lock()
        self._pending = 0
        self.served = 0
        self.succeeded = 0
        self.failed = 0  # answered success=false (bad request, solver failure, timeout)
        self.busy = 0  # answered "busy" at once
        self.refused = 0  # answered success=false while not active
        self._solve_times: deque[float] = deque(maxlen=10_000)
        self._period_solve_times: list[float] = []
        self._since = diagnostics.Since()
        self._plan_pub: Any = None
        self.diagnostics = diagnostics.Diagnostics(self, "ocp", self.managed_report(self._report))
        self.create_service(
            ComputeTrajectory,
            names.OCP_SERVICE,
            self._on_request,
            qos_profile=qos.SERVICE_QOS,  # a burst waits here instead of being dropped
            callback_group=ReentrantCallbackGroup(),
        )

    def _configure(self) -> str:
        self._pool = _solver_pool()
        self._plan_pub = self.own(
            self.create_lifecycle_publisher(Path, names.PLAN_TOPIC, qos.PATH_QOS)
        )
        return (
            f"OCP service ready: method={self._param('method')}, "
            f"objective={self._param('objective')}, "
            f"control_points={self._param('control_points')}, "
            f"timeout_s={self._param('timeout_s')}, max_pending={self.max_pending}"
        )

    def _activate(self) -> str:
        return f"answering {self.get_namespace().rstrip('/')}/{names.OCP_SERVICE}"

    def _deactivate(self) -> str:
        return "new requests are refused (a solve in progress finishes)"

    def _release(self) -> str:
        self._stop_pool()
        self._plan_pub = None
        return f"solver process stopped ({self.served} requests solved)"

    def _param(self, name: str) -> Any:
        return params.value(self, name, PARAMETERS)

    def _on_request(
        self, request: ComputeTrajectory.Request, response: ComputeTrajectory.Response
    ) -> ComputeTrajectory.Response:
        if not self.active:
            with self._count_lock:
                self.refused += 1
            response.success = False
            response.message = f"refused: {self.refusal()}"
            return response
        with self._count_lock:
            busy = self._pending >= self.max_pending
            if not busy:
                self._pending += 1
        if busy:
            with self._count_lock:
                self.busy += 1
            response.success = False
            response.message = f"busy: {self._pending} requests in progress; try again later"
            return response
        try:
            response = self._solve(request, response)
            self._count(response)
            return response
        except Exception as exc:  # the node never dies of a request
            self.get_logger().error(f"request failed: {exc!r}")
            response = ComputeTrajectory.Response()
            response.success = False
            response.message = f"internal error: {exc!r}"
            self._count(response)
            return response
        finally:
            with self._count_lock:
                self._pending -= 1

    def _count(self, response: ComputeTrajectory.Response) -> None:
        """Count an answer; publish a successful one's plan on ocp/plan."""
        with self._count_lock:
            if response.success:
                self.succeeded += 1
            else:
                self.failed += 1
            if response.solve_time > 0:
                self._solve_times.append(response.solve_time)
                self._period_solve_times.append(response.solve_time)
        if response.success and len(response.positions) and self._plan_pub is not None:
            now_ns = self.get_clock().now().nanoseconds
            self._plan_pub.publish(plan_path_msg(response, now_ns))

    def _report(self) -> diagnostics.Report:
        """/diagnostics of the last period (rules: pd_ros_common.diagnostics)."""
        with self._count_lock:
            times = np.asarray(self._solve_times, dtype=float)
            period, self._period_solve_times = self._period_solve_times, []
            pending, busy, failed = self._pending, self.busy, self.failed
            d = self._since(busy=busy, failed=failed)
            succeeded = self.succeeded

        def pct(q: float) -> float:
            return float(np.percentile(times, q)) if times.size else float("nan")

        r = diagnostics.Report(ok_message="solving" if pending else "idle")
        r.values = {
            "pending requests": pending,
            "max_pending": self.max_pending,
            "answered": succeeded + failed + busy,
            "succeeded": succeeded,
            "failed": failed,
            "busy answers": busy,
            "refused (not active)": self.refused,
            "solved (last period)": len(period),
            "solve time p50 (s)": pct(50),
            "solve time p99 (s)": pct(99),
            "solve time max (s)": float(times.max()) if times.size else float("nan"),
            "last solve time (s)": float(times[-1]) if times.size else float("nan"),
        }
        r.rule(diagnostics.WARN, d["busy"] > 0, f"{int(d['busy'])} request(s) answered busy")
        r.rule(diagnostics.WARN, d["failed"] > 0, f"{int(d['failed'])} request(s) failed")
        return r

    def _solve(
        self, request: ComputeTrajectory.Request, response: ComputeTrajectory.Response
    ) -> ComputeTrajectory.Response:
        position = from_vec3(request.position).tolist()
        velocity = from_vec3(request.velocity).tolist()
        method = request.method or self._param("method")
        objective = request.objective or self._param("objective")
        n_control = int(request.control_points) or self._param("control_points")
        timeout = float(request.timeout) or self._param("timeout_s")
        why = ocp.check_request(
            position,
            velocity,
            request.mass,
            method=method,
            objective=objective,
            n_control=n_control,
            timeout_s=timeout,
        )
        if why is not None:  # refuse at once, without queueing behind a running solve
            response.success = False
            response.message = f"bad request: {why}"
            self.get_logger().warning(response.message)
            return response
        t_arrive = time.monotonic()
        queued = self._solve_lock.locked()  # an earlier solve is running
        with self._solve_lock:
            waited = time.monotonic() - t_arrive
            left = timeout - waited
            if left <= 0:
                response.success = False
                response.message = (
                    f"timeout: waited {waited:.1f} s for an earlier solve"
                    if queued
                    else f"timeout: {timeout:g} s is too short to start a solve"
                )
                return response
            res = self._solve_in_process(
                position,
                velocity,
                float(request.mass),
                method=method,
                objective=objective,
                n_control=n_control,
                timeout_s=left,
            )
        fill_ocp_response(res, response)
        if res.success and request.discretise:
            self._discretise(res, response)
        self.served += 1
        text = (
            f"request {self.served} from x = {np.round(position, 1).tolist()} m: "
            f"success={res.success} ({res.message}); {method}/{objective}, "
            f"t_f {res.time_of_flight:.2f} s, fuel {res.fuel:.1f} kg, "
            f"solve {res.solve_time:.2f} s"
        )
        if res.success:  # one call site per severity (rclpy insists)
            self.get_logger().info(text)
        else:
            self.get_logger().warning(text)
        return response

    def _solve_in_process(self, *args: Any, **kwargs: Any) -> ocp.OCPResult:
        """`ocp.solve` in the solver process (caller holds the solve lock)."""
        t0 = time.monotonic()
        base = {"method": kwargs["method"], "objective": kwargs["objective"]}
        pool = self._pool
        if pool is None:  # released (cleanup) while this request waited
            return ocp.OCPResult(False, "refused: the solver process was released", **base)
        try:
            future = pool.submit(ocp.solve, *args, **kwargs)
            return future.result(timeout=kwargs["timeout_s"] + SOLVER_GRACE_S)
        except FutureTimeout:
            why = f"timeout: the solver did not return within {kwargs['timeout_s']:.1f} s"
        except BrokenProcessPool as exc:
            why = f"solver process died: {exc}"
            if self._pool is None:  # released (cleanup) while solving
                return ocp.OCPResult(False, f"{why} (released)", **base)
        self.get_logger().error(f"{why}; starting a new solver process")
        self._restart_pool()
        return ocp.OCPResult(False, why, solve_time=time.monotonic() - t0, **base)

    def _restart_pool(self) -> None:
        old = self._pool
        if old is None:
            return
        for proc in list(getattr(old, "_processes", {}).values()):
            proc.terminate()
        old.shutdown(wait=False, cancel_futures=True)
        self._pool = _solver_pool()

    def _stop_pool(self) -> None:
        # Stop the solver process and join the pool's manager thread now: left to the
        # interpreter's exit hook, it writes to a closed pipe and prints a traceback.
        pool, self._pool = self._pool, None
        if pool is not None:
            procs = list(getattr(pool, "_processes", {}).values())
            for proc in procs:
                proc.terminate()
            for proc in procs:
                proc.join(timeout=2.0)
            pool.shutdown(wait=True, cancel_futures=True)

    def destroy_node(self) -> None:
        self._stop_pool()
        super().destroy_node()

    def _discretise(self, res: ocp.OCPResult, response: ComputeTrajectory.Response) -> None:
        """Discretised actions of Eqs. 5-7 (`pd_core.discretise.discretise`, (7, 7, 3) actions)."""
        try:
            run = discretise(res)
        except Exception as exc:  # report, do not fail the trajectory that was solved
            response.message += f"; discretisation failed: {exc}"
            return
        response.actions = [int(a) for a in np.asarray(run.actions).reshape(-1)]
        start = np.asarray(run.initial_state, dtype=float)
        response.discrete_initial_position = vec3(start)
        response.discrete_landed = bool(run.landed)


def main(args: list[str] | None = None) -> int:
    return run_node(
        NODE_NAME,
        __doc__ or "",
        PARAMETERS,
        OcpNode,
        args,
        threads=lambda node: node.max_pending + 2,
    )


if __name__ == "__main__":
    sys.exit(main())
