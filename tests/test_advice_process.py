"""An advisor in a child process: same answers, one-line failures, a dead child never raises."""

from __future__ import annotations

import functools

import pytest

from pirl.advice.oracle import OracleAdvisor
from pirl.advice.process import ProcessAdvisor
from pirl.advice.state import advice_requests
from pirl.env import make_vec_env


def _missing_model() -> OracleAdvisor:
    raise FileNotFoundError("no model folder /nowhere/model")


def test_answers_equal_the_advisor_in_process():
    venv = make_vec_env(3, seed=2, size=(12, 10, 3), wind_prob=0.0)
    venv.reset()
    local = OracleAdvisor()
    remote = ProcessAdvisor(OracleAdvisor)
    try:
        assert (remote.name, remote.label, remote.wants_view) == (
            local.name, local.label, True,
        )  # fmt: skip
        assert remote.settings_key() == local.settings_key()
        prompts, views = advice_requests(venv.world, range(3), remote)
        got = remote.advise(prompts, views)
        want = local.advise(prompts, views)
        assert [a.recommendation for a in got] == [a.recommendation for a in want]
        assert all(a.error is not None for a in remote.advise(prompts, None))  # no views
    finally:
        remote.close()
        remote.close()  # twice is fine


def test_a_child_that_cannot_build_its_advisor_says_why():
    with pytest.raises(OSError, match="no model folder /nowhere/model"):
        ProcessAdvisor(functools.partial(_missing_model))


def test_a_dead_child_gives_error_answers():
    remote = ProcessAdvisor(OracleAdvisor)
    remote._proc.kill()
    remote._proc.join()
    answers = remote.advise(["a", "b"])
    assert [a.recommendation for a in answers] == [None, None]
    assert all("advisor process ended" in a.error for a in answers)
    remote.close()
