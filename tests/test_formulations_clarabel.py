"""The Clarabel adapter reads where cvxpy put each variable from cvxpy's compiled problem
(`param_prob.var_id_to_col`, an internal: pyproject.toml pins the tested cvxpy range).
If a cvxpy release moves or reorders it, these tests fail with that name in the message."""

from __future__ import annotations

import cvxpy as cp
import numpy as np
import pytest

from opfbench.formulations.solvers.clarabel_adapter import ParametricConeProgram, relaxation_settings, variable_columns


def _problem() -> tuple[cp.Problem, cp.Variable, cp.Variable, cp.Variable]:
    """min Σx + 2·y  s.t.  x ≥ θ (data, 3 entries), y ≥ ‖x − 1‖, y ≤ 10."""
    theta = cp.Variable(3, name="theta")
    x, y = cp.Variable(3, name="x"), cp.Variable(name="y")
    constraints = [x >= theta, cp.SOC(y, x - 1), y <= 10]
    return cp.Problem(cp.Minimize(cp.sum(x) + 2 * y), constraints), theta, x, y


def test_variable_columns_cover_every_variable_once():
    problem, theta, x, y = _problem()
    data, _, _ = problem.get_problem_data(cp.CLARABEL)
    columns = variable_columns(data)
    n = data["A"].shape[1]
    spans = sorted((columns[v.id], columns[v.id] + v.size) for v in (theta, x, y))
    assert spans[0][0] == 0 and spans[-1][1] == n  # the variables tile the columns
    assert all(a[1] == b[0] for a, b in zip(spans, spans[1:], strict=False))


@pytest.mark.parametrize("theta_value", [[2.0, 0.5, 1.0], [1.0, 1.0, 1.0], [3.0, 2.0, 1.5]])
def test_values_read_at_those_columns_are_cvxpys_own(theta_value):
    """The adapter's answer (data in the offset, values read at the columns) equals cvxpy's
    own solve of the same problem with the data pinned."""
    problem, theta, x, y = _problem()
    program = ParametricConeProgram(problem, (theta,), relaxation_settings())
    answer = program.solve(program.offsets(np.array([theta_value]))[0])
    assert answer.solved
    value = program.reader(answer.x)
    pinned = cp.Problem(problem.objective, problem.constraints + [theta == theta_value])
    pinned.solve(solver=cp.CLARABEL)
    np.testing.assert_allclose(value(x), x.value, atol=1e-6)
    np.testing.assert_allclose(value(y), y.value, atol=1e-6)
    assert answer.primal == pytest.approx(pinned.value, rel=1e-7)
    assert np.all(value(x) >= np.array(theta_value) - 1e-8)  # the data entered where they belong


def test_a_cvxpy_without_the_internal_fails_loudly():
    with pytest.raises(RuntimeError, match=r"var_id_to_col.*pinned in opfbench's pyproject.toml"):
        variable_columns({"A": None})
