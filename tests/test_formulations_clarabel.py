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


def _quadratic() -> tuple[cp.Problem, cp.Variable, cp.Variable]:
    """min ‖x − c‖² + x₀·x₁ terms (a full P) + 3  s.t.  x ≥ θ (data), Σx ≤ 4, x ≤ 2: the
    optimum moves with θ wherever a bound binds, so a zero P gives another answer."""
    theta, x = cp.Variable(3, name="theta"), cp.Variable(3, name="x")
    weight = np.array([[2.0, 0.5, 0.0], [0.5, 1.0, 0.2], [0.0, 0.2, 3.0]])
    objective = cp.quad_form(x, weight) - np.array([1.0, -2.0, 4.0]) @ x + 3.0
    return cp.Problem(cp.Minimize(objective), [x >= theta, cp.sum(x) <= 4, x <= 2]), theta, x


@pytest.mark.parametrize("screening", [True, False])
def test_a_quadratic_objective_is_solved_as_cvxpy_solves_it(screening):
    """The P matrix reaches Clarabel (issue 28: a zero P returned a wrong optimum silently),
    the objective's constant is reported, and bound screening keeps the answer."""
    problem, theta, x = _quadratic()
    program = ParametricConeProgram(problem, (theta,), relaxation_settings(), screening=screening)
    thetas = np.array([[0.0, -1.0, 0.0], [0.6, 0.3, 1.0], [-1.0, -1.0, -1.0], [0.6, 0.3, 1.0]])
    for b, theta_value in zip(program.offsets(thetas), thetas, strict=True):
        answer = program.solve(b)
        pinned = cp.Problem(problem.objective, problem.constraints + [theta == theta_value])
        pinned.solve(solver=cp.CLARABEL)
        assert answer.solved
        np.testing.assert_allclose(program.reader(answer.x)(x), x.value, atol=1e-6)
        assert answer.primal == pytest.approx(pinned.value, abs=1e-6) and answer.dual == pytest.approx(pinned.value, abs=1e-6)


def test_a_data_variable_in_the_objective_is_refused():
    """A term of θ itself in c or P would make a solve depend on θ beyond the offsets."""
    theta, x = cp.Variable(2, name="theta"), cp.Variable(2, name="x")
    for objective in (cp.sum_squares(x) + cp.sum_squares(theta), cp.quad_form(theta, np.eye(2)), cp.sum(x) + theta[0]):
        with pytest.raises(ValueError, match="data variables must not enter the objective"):
            ParametricConeProgram(cp.Problem(cp.Minimize(objective), [x >= theta]), (theta,), relaxation_settings())
