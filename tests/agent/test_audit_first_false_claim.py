"""When a lie first came due: the audit's rules applied to the truth (experiments time
detection from there)."""

import dataclasses

import numpy as np
import pytest

from trustfg.agent.audit import false_claim_times, first_false_claim, sustained_lie
from trustfg.agent.config import TrustConfig
from trustfg.agent.gp import Plan

CONFIG = TrustConfig()  # tolerance 0.15 m + 0.15 m/s of lag; notice 0.5 s; every 0.2 s for 3 s


def standing(at=(0.0, 0.0), t0=0.0) -> Plan:
    return Plan(t0, 0.5, np.tile(at, (9, 1)), np.zeros((9, 2)))


def leaving(t0=0.0) -> Plan:
    """Stands for 1 s, then drives +x at 0.6 m/s."""
    x = np.r_[0.0, 0.0, 0.0, 0.3 * np.arange(1, 7)]
    return Plan(t0, 0.5, np.c_[x, np.zeros(9)], np.c_[np.r_[0, 0, 0, [0.6] * 6], np.zeros(9)])


def at_rest(times):
    return np.zeros((len(np.atleast_1d(times)), 2))


def test_a_displaced_plan_comes_due_at_its_stamp():
    told = [(1.0, standing(at=(0.4, 0.0), t0=1.0), True)]
    assert first_false_claim(told, at_rest, CONFIG) == 1.0


def test_a_false_future_comes_due_when_its_time_comes_if_it_is_still_held():
    """Says it leaves at 1 s at 0.6 m/s, stays: the claim 0.6 (t - 1) m ahead of a car
    that never moved passes the tolerance 0.15 + 0.15 t m after t = 1.67 s."""
    told = [(0.0, leaving(), True)]
    due = first_false_claim(told, at_rest, CONFIG)
    assert due is not None and 1.6 <= due <= 1.8 + 1e-9
    lag = due
    assert np.linalg.norm(leaving().position_at(due)[0]) > CONFIG.transparency_tolerance_m + lag * CONFIG.audit_tolerance_growth_mps


def test_a_lie_withdrawn_with_notice_never_comes_due_and_would_without_the_notice():
    told = [(0.0, leaving(), True)] + [(0.2 * k, standing(t0=0.2 * k), False) for k in range(1, 20)]
    assert first_false_claim(told, at_rest, CONFIG) is None
    held_for_good = dataclasses.replace(CONFIG, audit_notice_s=10.0)
    assert first_false_claim(told, at_rest, held_for_good) is not None


def test_a_truthful_plan_is_never_a_lie_even_when_it_misses():
    told = [(0.0, leaving(), False)]  # an honest change of mind: not the liar's lie
    assert first_false_claim(told, at_rest, CONFIG) is None


def test_nothing_before_the_first_lie_counts():
    told = [(0.0, leaving(), True)]
    assert first_false_claim(told, at_rest, CONFIG, after=2.5) == 2.6


def test_a_lie_is_sustained_from_the_start_of_the_first_run_that_lasts():
    period = CONFIG.audit_period_s
    brief = np.arange(-0.4, 0.25, 0.1)  # 0.6 s of lies, then the liar stands
    lasting = np.arange(0.9, 3.0, 0.1)
    assert sustained_lie(np.r_[brief, lasting], CONFIG, 1.0) == pytest.approx(0.9)
    assert sustained_lie(np.r_[brief, lasting], CONFIG, 0.5) == pytest.approx(-0.4)
    assert sustained_lie(brief, CONFIG, 1.0) is None
    assert sustained_lie(np.empty(0), CONFIG, 1.0) is None
    paused = np.r_[np.arange(0.0, 0.6, period), np.arange(0.6 + 2.5 * period, 1.6, period)]  # a pause too long
    assert sustained_lie(paused, CONFIG, 1.0) is None
    steady = np.arange(0.0, 1.3, 2 * period)  # a lie every two audit periods still goes on
    assert sustained_lie(steady, CONFIG, 1.0) == 0.0


def test_the_first_false_claim_is_the_first_of_all_the_times_lies_came_due():
    told = [(0.0, leaving(), True), (0.5, standing(at=(0.4, 0.0), t0=0.5), True)]
    due = false_claim_times(told, at_rest, CONFIG)
    assert list(due) == sorted(set(due)) and first_false_claim(told, at_rest, CONFIG) == due[0] == 0.5
