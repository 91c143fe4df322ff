"""Bound screening of the conic programs (`clarabel_adapter.ParametricConeProgram`): a screened answer
is the full program's optimum, wrong guesses are refused, and the answer does not depend
on them."""

from __future__ import annotations

import numpy as np
import pytest

from opfbench.bench.paper_day import paper_day_scenario
from opfbench.formulations.model import build_problem_model
from opfbench.formulations.models.conic import data_vector
from opfbench.formulations.problem import snapshot_data
from opfbench.io import load_network
from opfbench.scenario import Scenario


def _offsets(relax, scenario: Scenario, k: float) -> np.ndarray:
    data = snapshot_data(scenario, k)
    return relax.program.offsets(data_vector(data.s_fixed, data.q_limit))


@pytest.mark.parametrize("k", [0.0, 0.4])
def test_screened_answers_are_the_full_programs_optimum_on_the_paper_day(k):
    """Every 6th minute of the paper day: most answers screened; each screened point
    within every dropped bound (v limits, DER Q limits); its bound equal to the full
    program's within 3e-7 relative (measured ≤ 1.9e-7) and never above the full program's
    primal objective by more than that."""
    day = paper_day_scenario("paper33")
    relax = build_problem_model("relaxation", day.net)
    program, problem = relax.program, relax.problem
    offsets = _offsets(relax, day, k)[::6]
    data = snapshot_data(day, k)
    q_limit = data.q_limit[::6]
    screened = 0
    for b, limit in zip(offsets, q_limit, strict=True):
        answer = program.solve(b)
        full, statuses, _ = program.full.solve(b)
        assert answer.solved and statuses[-1] == "Solved"
        bound, full_bound = min(answer.primal, answer.dual), min(full.obj_val, full.obj_val_dual)
        assert bound == pytest.approx(full_bound, rel=3e-7)
        assert bound <= full.obj_val * (1 + 3e-7)
        value = program.reader(answer.x)
        v = value(relax.v)[problem.others]
        assert np.all(v >= problem.vm_min**2 - 1e-9) and np.all(v <= problem.vm_max**2 + 1e-9)
        assert np.all(np.abs(value(relax.q)) <= limit + 1e-9)
        screened += answer.screened
    assert screened >= 0.9 * len(offsets), screened


def test_a_wrong_guess_is_refused_and_changes_no_digit():
    """Guessing that every DER sits at its upper Q limit at light load (where they do not)
    fails the check; the answer is the one a solver without that guess gives, to the digit."""
    net = load_network("paper33")
    relax, fresh = build_problem_model("relaxation", net), build_problem_model("relaxation", net)
    b = _offsets(relax, Scenario.snapshot(net, 0.5, 0.7), 0.0)[0]
    program = relax.program
    upper = tuple(
        int(i)
        for i in np.flatnonzero(program._bound_coef > 0)
        if program._bound_col[i] in range(program._var_col[relax.q.id], program._var_col[relax.q.id] + relax.q.size)
    )
    program._guess = upper
    wrong = program.solve(b)
    right = fresh.program.solve(b)
    assert wrong.solves > right.solves and wrong.screened and right.screened
    np.testing.assert_array_equal(wrong.x, right.x)
    assert wrong.primal == right.primal and wrong.dual == right.dual
    assert program._guess != upper


def test_a_q_limit_of_zero_fixes_the_der_at_zero():
    """At night with the PV disconnected its Q limit is 0 (its two bounds coincide): the
    screened program keeps its upper row as Q = 0 and accepts a multiplier of either sign."""
    net = load_network("paper33")
    relax = build_problem_model("relaxation", net)
    scenario = Scenario.snapshot(net, 0.8, 0.0)
    data = snapshot_data(scenario, 0.0)
    limit = data.q_limit[0].copy()
    limit[:-1] = 0.0  # every DER but the last without Q (as the PV at night, disconnected)
    b = relax.program.offsets(data_vector(data.s_fixed, limit[None]))[0]
    first = relax.program.solve(b)  # no guess: the full program, then the screened one
    second = relax.program.solve(b)  # guessed right: one screened solve
    assert first.screened and second.screened and second.solves == 1 and first.solves == 2
    q = relax.program.reader(second.x)(relax.q)
    assert np.all(np.abs(q[:-1]) <= 1e-9) and abs(q[-1]) <= limit[-1] + 1e-9
    np.testing.assert_array_equal(first.x, second.x)
