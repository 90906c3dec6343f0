"""pd_core.ocp requests: bad states and settings are refused with one line, in microseconds."""

from __future__ import annotations

import numpy as np
import pytest

from pd_core import ocp
from pd_core.demonstrations.open_loop import table1_initial_states
from pd_core.ocp.request import MAX_CONTROL_POINTS, MAX_TIMEOUT_S, MIN_TIMEOUT_S

S0 = table1_initial_states()[0]


@pytest.mark.parametrize(
    ("pos", "vel", "mass", "words"),
    [
        ([np.nan, 0, 2500], [0, 0, -80], 2000, "NaN"),
        ([0, 0, 2500], [0, np.inf, -80], 2000, "NaN or infinite"),
        ([0, 0, 2500], [0, 0, -80], 0.0, "mass"),
        ([0, 0, 2500], [0, 0, -80], -5.0, "mass"),
        ([0, 0, 0.0], [0, 0, -80], 2000, "altitude"),
        ([0, 0, -10.0], [0, 0, -80], 2000, "altitude"),
        ([0, 0, 5e5], [0, 0, -80], 2000, "absurd"),
        ([0, 0, 2500], [0, 0, -5e3], 2000, "absurd"),
        ([0, 0, 2500], [0, 0, -80], 900.0, "dry mass"),
        ([0, 2500], [0, 0, -80], 2000, "3 position"),
    ],
)
def test_bad_requests_fail_with_a_message(pos: list, vel: list, mass: float, words: str) -> None:
    r = ocp.solve(pos, vel, mass)
    assert not r.success
    assert words.lower() in r.message.lower()
    assert ocp.check_request(pos, vel, mass) is not None


def test_bad_options_fail_with_a_message() -> None:
    s = S0
    assert "unknown method" in ocp.solve(s[0:3], s[3:6], s[6], method="nope").message
    assert "unknown objective" in ocp.solve(s[0:3], s[3:6], s[6], objective="x").message
    assert "n_control" in ocp.solve(s[0:3], s[3:6], s[6], n_control=1).message
    assert ocp.check_request(s[0:3], s[3:6], s[6]) is None


@pytest.mark.parametrize(
    ("settings", "words"),
    [
        ({"n_control": 100000}, f"[2, {MAX_CONTROL_POINTS}]"),
        ({"n_control": 4294967295}, "n_control"),
        ({"n_control": 2.5}, "n_control"),
        ({"n_control": True}, "n_control"),
        ({"timeout_s": 1e-6}, f"[{MIN_TIMEOUT_S:g}, {MAX_TIMEOUT_S:g}] s"),
        ({"timeout_s": float("nan")}, "timeout_s"),
        ({"timeout_s": 1e9}, "timeout_s"),
        ({"method": "nope"}, "unknown method"),
        ({"objective": "x"}, "unknown objective"),
    ],
)
def test_out_of_range_settings_are_refused_with_one_line(settings: dict, words: str) -> None:
    why = ocp.check_request(S0[0:3], S0[3:6], S0[6], **settings)
    assert why is not None and words in why and "\n" not in why
    r = ocp.solve(S0[0:3], S0[3:6], S0[6], **settings)
    assert not r.success and r.message == why


def test_settings_at_the_bounds_are_accepted() -> None:
    assert ocp.check_request(S0[0:3], S0[3:6], S0[6], n_control=MAX_CONTROL_POINTS) is None
    assert ocp.check_request(S0[0:3], S0[3:6], S0[6], n_control=2, timeout_s=MIN_TIMEOUT_S) is None


def test_problem_refuses_what_check_request_refuses() -> None:
    with pytest.raises(ValueError, match="altitude"):
        ocp.Problem([0, 0, -1.0], [0, 0, 0], 2000.0)
    with pytest.raises(ValueError, match="n_control"):
        ocp.Problem(S0[0:3], S0[3:6], S0[6], n_control=1)
    assert np.array_equal(ocp.Problem(S0[0:3], S0[3:6], S0[6]).x0, S0[0:3])
