"""The OPF problem's strategies (paper §III): `acopf` and `acopf-paper` — the problem's exact
model — and `socp` — its relaxation, the certified lower bound. Which model serves them on
a network is the models' declaration (`model.model_for`: today the polar AC OPF, and
DistFlow on radial feeders, Jabr's on meshed ones); the generic runner runs them
(`runner`)."""

from __future__ import annotations

from opfbench.formulations.acopf_options import ACOPF_SOLVERS, FALLBACKS, AcopfSolver, Fallback
from opfbench.formulations.model import SLACK_EXPORT, model_for
from opfbench.formulations.problem import check_supported
from opfbench.formulations.runner import run_problem_model
from opfbench.formulations.three_phase import run_phase
from opfbench.multiphase import PhaseNetwork
from opfbench.network import Network
from opfbench.registry.options import Option
from opfbench.registry.specs import SUPPORTS, UNBALANCED, strategy
from opfbench.result import StrategyResult
from opfbench.scenario import Scenario

SOLVER = Option(
    "solver",
    "auto",
    "auto: the SOCP certifies the AC optimum where it can, IPOPT solves the rest; ipopt: IPOPT on every step",
    choices=ACOPF_SOLVERS,
    setting="acopf_solver",
)


def check_exact(net: Network | PhaseNetwork) -> None:
    """NetworkError before any work unless the problem is modelled on `net` and an exact
    model and a relaxation serve it (the AC OPF's bound and fast path) — on a three-phase
    feeder an exact model (its bound, `sdp3`, is computed apart: `three_phase.bound`)."""
    if isinstance(net, PhaseNetwork):
        model_for("exact", net)
        return
    check_supported(net)
    model_for("exact", net)
    model_for("relaxation", net)


def check_relaxation(net: Network) -> None:
    """NetworkError before any work unless the problem is modelled on `net` and a relaxation serves it."""
    check_supported(net)
    model_for("relaxation", net)


FALLBACK = Option("fallback", "chain", "chain: warm → cold IPOPT → SOCP → no action; paper: no action", choices=FALLBACKS)
CURTAIL = Option(
    "curtail",
    False,
    "the optimum may curtail the DER's active power too, at the cost of the energy curtailed (objective: losses + "
    "curtailed power; formulations.curtail)",
)


@strategy(
    "acopf-paper",
    kind="formulation",
    summary="AC OPF under the paper's setup: slack may not export, failure → no action",
    options=(SOLVER,),
    fixed={"fallback": "paper", "slack_export": False},
    role="exact",
    supports=SUPPORTS + UNBALANCED,
    network_check=check_exact,
)
@strategy(
    "acopf",
    kind="formulation",
    summary="centralized AC OPF (IPOPT), fallback chain ending at an AC-feasible point",
    options=(FALLBACK, SLACK_EXPORT, SOLVER, CURTAIL),
    bound_rank=1,
    role="exact",
    supports=SUPPORTS + UNBALANCED,
    network_check=check_exact,
)
def run_acopf(
    scenario: Scenario,
    k: float,
    *,
    slack_export: bool = True,
    fallback: Fallback = "chain",
    solver: AcopfSolver = "auto",
    curtail: bool = False,
) -> StrategyResult:
    """The AC OPF on every snapshot of `scenario` with reserve k (`runner.run_exact`); with
    `curtail` the one that may curtail the DER's active power (`curtail.run_curtailing`)."""
    if curtail and scenario.three_phase:
        return run_phase(
            model_for("exact", scenario.net),
            scenario,
            k,
            name="acopf",
            slack_export=slack_export,
            fallback=fallback,
            curtail=True,
        )
    if curtail:
        from opfbench.formulations.curtail import run_curtailing

        return run_curtailing(scenario, k, slack_export=slack_export, fallback=fallback, solver=solver)
    return run_problem_model("exact", "acopf", scenario, k, slack_export=slack_export, fallback=fallback, solver=solver)


@strategy(
    "socp",
    kind="formulation",
    summary="SOCP relaxation (Clarabel): certified lower bound; its Q evaluated by AC power flow",
    options=(SLACK_EXPORT,),
    bound_rank=0,
    role="relaxation",
    network_check=check_relaxation,
    snapshot_wise=True,  # a relaxation solves each snapshot from its data alone (`model.BatchModel`)
)
def run_socp(scenario: Scenario, k: float, *, slack_export: bool = True) -> StrategyResult:
    """The relaxation's setpoints on every snapshot, evaluated by the AC power flow
    (`runner.run_batch`); its optimum is a certified lower bound on the achievable losses."""
    return run_problem_model("relaxation", "socp", scenario, k, slack_export=slack_export)
