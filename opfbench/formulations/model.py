"""What a formulation model is, how it is registered, and which model serves which strategy
on which network — declared by the models, looked up here.

A model is one file under `formulations/models/` (found and imported by `load_models`) or a
plugin (`--plugin FILE.py`, as a local rule is), and declares itself with `@formulation`:

    @formulation("lindistflow", role="approximation", networks=("radial",), summary="…")
    class LinDistFlow(ConicModel): ...

`role` says what the model's objective means for the benchmark (`registry.specs.MEANING`):
an **exact** model's optimum is the AC optimum; a **relaxation**'s is a certified lower
bound on it; an **approximation**'s is an estimate. A model is built for one network and
slack rule (`build(net, slack_export)`, once per thread) and answers snapshots:

- an exact model (`ExactModel`) solves one snapshot at a time, warm-started from its last
  answer (an NLP: `models.polar_ac`);
- a relaxation or an approximation (`BatchModel`) solves snapshots independently from
  their data (`models.conic.ConicModel`), so the runner shares its solves by data.

With `serves_problem=True` a model is a candidate for the OPF problem's model of its role —
the exact model behind `acopf` and `acopf-paper`, the relaxation behind `socp` and the AC
OPF's bound and fast path (`formulations.opf_strategies`); among the candidates that model a
network's class (`networks`), the lowest `preference` serves it. Otherwise the model is a
strategy of its own, named as the model, run by the generic runner (`formulations.runner`:
its setpoints AC-evaluated, statuses, fallback to no action). Either way the setpoints are
evaluated by the AC power flow and every figure in the tables is the AC one.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

import numpy as np

from opfbench.errors import NetworkError
from opfbench.formulations.problem import OpfProblem, check_supported
from opfbench.formulations.solver_cache import per_thread
from opfbench.registry.options import Option
from opfbench.registry.specs import (
    MODELS,
    SUPPORTS,
    ModelSpec,
    Role,
    StrategySpec,
    network_class,
    register,
    register_model,
    source_of,
)

if TYPE_CHECKING:
    from opfbench.formulations.models.conic import SnapshotSolve
    from opfbench.formulations.solvers.ipopt_adapter import IpoptSolve
    from opfbench.multiphase import PhaseNetwork
    from opfbench.network import Network
    from opfbench.result import StrategyResult
    from opfbench.scenario import Scenario

M = TypeVar("M", bound=type)
SLACK_EXPORT = Option("slack_export", True, "the slack may export (reverse power flow); false: slack P ≥ 0")


class ExactModel(Protocol):
    """An exact model: `solve` one snapshot (fixed injections (n_bus,) complex p.u., usable
    Q limits (n_der,) p.u.), cold or warm from a previous answer."""

    problem: OpfProblem

    def solve(self, s_fixed: np.ndarray, q_limit: np.ndarray, start: IpoptSolve | None = None) -> IpoptSolve: ...


class BatchModel(Protocol):
    """A relaxation or approximation: `solve_data` solves snapshots given as data vectors
    (`models.conic.data_vector`), each independently of the others."""

    problem: OpfProblem

    def solve_data(self, thetas: np.ndarray) -> Sequence[SnapshotSolve]: ...


def formulation(
    name: str,
    *,
    role: Role,
    summary: str,
    networks: tuple[str, ...] = SUPPORTS,
    serves_problem: bool = False,
    preference: int = 0,
) -> Callable[[M], M]:
    """Register the decorated model class (`cls(net, slack_export)`) as the formulation
    model `name` (module docstring); InputError for a name taken or not valid."""

    def decorate(cls: M) -> M:
        source = source_of(cls.__module__)
        register_model(ModelSpec(name, role, cls, summary, networks, serves_problem, preference, source))
        if not serves_problem:
            register(
                StrategySpec(
                    name,
                    "formulation",
                    summary,
                    _own_runner(name),
                    options=(SLACK_EXPORT,),
                    role=role,
                    supports=networks,
                    network_check=_check_network,
                    snapshot_wise=role != "exact",  # a batch model solves each snapshot from its data alone
                    source=source,
                    module=cls.__module__,
                )
            )
        return cls

    return decorate


def _check_network(net: Network | PhaseNetwork) -> None:
    """The OPF problem's checks of a balanced network (`problem.check_supported`); a
    three-phase feeder's class is checked by `supports`, the rest by the model's build."""
    from opfbench.multiphase import PhaseNetwork

    if not isinstance(net, PhaseNetwork):
        check_supported(net)


def _own_runner(name: str) -> Callable[..., StrategyResult]:
    """The runner of a model that is a strategy of its own."""

    def run(scenario: Scenario, k: float, *, slack_export: bool = True) -> StrategyResult:
        from opfbench.formulations.runner import run_model

        return run_model(MODELS[name], scenario, k, slack_export=slack_export)

    return run


@functools.cache
def load_models() -> None:
    """Import every built-in model module (`formulations/models/`): each registers itself.
    Once per process: the built-in entries outlive `PROCESS.reset`, and the package scan
    costs about a millisecond, which per-row lookups (`catalog.rank`) used to pay each time."""
    from opfbench.formulations import models

    for info in pkgutil.iter_modules(models.__path__):
        importlib.import_module(f"{models.__name__}.{info.name}")


def model_for(role: Role, net: Network | PhaseNetwork) -> ModelSpec:
    """The model that serves the OPF problem's `role` on `net` (module docstring);
    NetworkError naming the network's class where none does."""
    load_models()
    kind = network_class(net)
    candidates = [m for m in MODELS.values() if m.serves_problem and m.role == role and kind in m.networks]
    if not candidates:
        raise NetworkError(f"{net.name}: no {role} formulation model serves {kind} networks")
    return min(candidates, key=lambda m: m.preference)


def build_problem_model(role: Role, net: Network, slack_export: bool = True) -> Any:
    """A new instance of the OPF problem's model of `role` on `net` — the caller's own (a
    model keeps solver state)."""
    return model_for(role, net).build(net, slack_export)


def built(model: ModelSpec, net: Network | PhaseNetwork, slack_export: bool = True) -> Any:
    """`model` built for `net`, once per network and slack rule in this thread (a model
    keeps solver state: never shared between threads)."""
    return per_thread(net, (model.name, bool(slack_export)), lambda: model.build(net, slack_export))
