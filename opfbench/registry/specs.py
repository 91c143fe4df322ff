"""The registry's two tables and how entries join them: every strategy (`StrategySpec`) and
every formulation model (`ModelSpec`), each registered once by the module that defines it
— the built-in ones and the plugins' through the same decorators:

- a local rule: `opfbench.strategies.registration.local_rule` (a target of the rule engine);
- a formulation model: `opfbench.formulations.model.formulation`;
- any other runner: `strategy` here (LFMA, the OPF problem's strategies).

Lookup by name, labels and the reference configurations are `registry.catalog`'s; loading
plugin files and entry points is `opfbench.plugins`'s (which says, while it loads one, what
the plugin's entries are registered under: `loading`).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from opfbench.errors import InputError
from opfbench.registry.options import Option, OptionValue
from opfbench.state import PROCESS

if TYPE_CHECKING:
    from opfbench.multiphase import PhaseNetwork
    from opfbench.network import Network
    from opfbench.result import StrategyResult
    from opfbench.scenario import Scenario

Kind = Literal["local", "formulation"]
#: A formulation model's role, and what its objective means for the benchmark.
Role = Literal["exact", "relaxation", "approximation"]
MEANING: dict[str, str] = {"exact": "optimum", "relaxation": "bound", "approximation": "estimate"}
#: Network classes a strategy or a model runs on (`network_class`).
SUPPORTS = ("radial", "meshed")
UNBALANCED = ("unbalanced-radial", "unbalanced-meshed")
"""The classes of three-phase (`PhaseNetwork`) feeders; no balanced model claims them."""
OPFBENCH = "opfbench"  # the source of the built-in entries
_NAME = re.compile(r"^[a-z0-9][a-z0-9._+-]*$")  # "+" joins rules run together: volt-var+volt-watt
Runner = Callable[..., "StrategyResult"]


def network_class(net: Network | PhaseNetwork) -> str:
    """The class of `net` that `supports` / `ModelSpec.networks` name: "meshed" or "radial",
    "unbalanced-meshed" or "unbalanced-radial" for a three-phase feeder."""
    from opfbench.multiphase import PhaseNetwork  # scipy: not at import (`opfbench --help` stays light)

    kind = "meshed" if net.meshed else "radial"
    return f"unbalanced-{kind}" if isinstance(net, PhaseNetwork) else kind


@dataclass(frozen=True)
class StrategySpec:
    """One registered strategy. `runner(scenario, k, **options)` runs it on every snapshot
    (options: the full, checked set, `fixed` included); `target`: a local rule's function
    of the measurements (its runner is the engine); `reads`: what a local rule
    measures (`strategies.rules.READS`), `closed_loop`: it reads what its own Q changes;
    `uses_forecast`: it reads a forecast (Algorithm 3's limit); `bound_rank`: it gives a
    certified lower bound on the losses (the summary takes the bound from the lowest rank
    present); `role`: a formulation's model role (`MEANING`: what its objective means);
    `supports`: network classes it runs on; `network_check(net)` refuses a network it
    cannot model, before any work; `check(options)` refuses option combinations;
    `columns`: extra per-step result columns (name → meaning, from `StrategyResult.extra`);
    `fit(name, training, options)`: a learned strategy's fit, `fit_options` the options it
    takes; `snapshot_wise`: each snapshot's result is a function of that snapshot's data
    alone, bit for bit, whatever other snapshots the scenario holds (the study runs such a
    strategy once on the distinct snapshots of several night modes; a solver warm-started
    along the scenario is not); `source`: "opfbench" or the plugin that registered it,
    `module` the module that declared it; `curtails`: a local rule that caps its DER's
    active power (its target returns `rules.Targets`)."""

    name: str
    kind: Kind
    summary: str
    runner: Runner
    target: Callable[..., Any] | None = None  # (S, n_der) MVAr, or `strategies.rules.Targets`
    reads: tuple[str, ...] = ()
    closed_loop: bool = False
    options: tuple[Option, ...] = ()
    fixed: dict[str, object] = field(default_factory=dict)
    uses_forecast: bool = False
    bound_rank: int | None = None
    role: Role | None = None
    supports: tuple[str, ...] = SUPPORTS
    network_check: Callable[[Network], None] | None = None
    check: Callable[[dict], None] | None = None
    columns: dict[str, str] = field(default_factory=dict)
    fit: Callable[..., Any] | None = None
    fit_options: tuple[str, ...] = ()
    snapshot_wise: bool = False
    source: str = OPFBENCH
    module: str = ""
    curtails: bool = False

    @property
    def option(self) -> dict[str, Option]:
        return {o.name: o for o in self.options}

    @property
    def learned(self) -> bool:
        """Fitted to the reference optimum: its parameters come from `train` or `params`."""
        return self.fit is not None

    @property
    def meaning(self) -> str | None:
        """What a formulation's objective is for the benchmark: optimum, bound or estimate."""
        return MEANING[self.role] if self.role is not None else None

    def fitted_options(self, ref: str) -> dict[str, OptionValue]:
        """The options that run a learned configuration with the fitted parameters `ref`:
        params=ref, and the fit's own options (train, rho, …) at their defaults — the fit
        used them; the engine's options stay the label's."""
        return {o.name: o.default for o in self.options if o.name in self.fit_options} | {"params": ref}

    def fit_rule(self, training: Any, options: Mapping[str, OptionValue]) -> Any:
        """A learned strategy's fitted parameters for `training` (`fit`)."""
        assert self.fit is not None, f"{self.name} is not a learned strategy"
        return self.fit(self.name, training, dict(options))

    def defaults(self) -> dict[str, OptionValue]:
        return {o.name: o.default for o in self.options}

    def resolve(self, given: Mapping[str, object]) -> dict[str, OptionValue]:
        """The options `given` (by name, Python values) checked and typed; InputError naming
        the strategy and the option for an unknown one or a bad value."""
        known = self.option
        unknown = sorted(set(given) - set(known))
        if unknown:
            allowed = ", ".join(known) or "none"
            raise InputError(f"strategy {self.name!r} takes no option {', '.join(unknown)} (options: {allowed})")
        out = {}
        for key, value in given.items():
            try:
                out[key] = known[key].coerce(value)
                known[key].validate(out[key])
            except InputError as exc:
                raise InputError(f"strategy {self.name!r}: option {key}: {exc}") from None
        return out

    def check_options(self, options: dict[str, OptionValue]) -> None:
        """The entry's own check of the full option set (defaults filled in)."""
        if self.check is not None:
            self.check(options)

    def check_network(self, net: Network | PhaseNetwork) -> None:
        """InputError / NetworkError for a network this strategy cannot run on (on a
        three-phase feeder: the local rules — one that measures needs DER — and the
        formulations whose `supports` name its class)."""
        from opfbench.multiphase import PhaseNetwork

        if isinstance(net, PhaseNetwork) and self.kind == "local":
            if not net.ders and self.reads:
                raise InputError(
                    f"strategy {self.name!r}: {net.name} has no DER; place them with ?der=BUS[.PHASE…]:KIND:MW (or --der)"
                )
            return
        kind = network_class(net)
        if kind not in self.supports:
            raise InputError(f"strategy {self.name!r} runs on {', '.join(self.supports)} networks; {net.name} is {kind}")
        if self.network_check is not None:
            self.network_check(net)  # type: ignore[arg-type]  # a three-phase feeder: a check that supports its class

    def describe(self) -> dict:
        """The entry as `opfbench strategies --json` lists it."""
        out = {
            "name": self.name,
            "kind": self.kind,
            "summary": self.summary,
            "reads": list(self.reads) if self.kind == "local" else ["the whole network (centralized)"],
            "closed_loop": self.closed_loop,
            "curtails": self.curtails,
            "learned": self.learned,
            "uses_forecast": self.uses_forecast,
            "lower_bound": self.bound_rank is not None,
            "snapshot_wise": self.snapshot_wise,
            "supports": list(self.supports),
            "options": [o.describe() for o in self.options],
            "fixed": {k: v for k, v in self.fixed.items()},
            "columns": dict(self.columns),
            "source": self.source,
        }
        if self.role is not None:
            out |= {"role": self.role, "objective": self.meaning}
        return out

    def record(self) -> dict:
        """What a run folder records of the strategy (its manifest's `strategies`): what a
        report needs to classify its rows without the strategy loaded (a plugin's)."""
        out: dict[str, object] = {
            "kind": self.kind,
            "summary": self.summary,
            "source": self.source,
            "uses_forecast": self.uses_forecast,
            "lower_bound": self.bound_rank is not None,
        }
        if self.role is not None:
            out |= {"role": self.role, "objective": self.meaning}
        return out

    def run(self, scenario: Scenario, k: float, label: str, options: dict[str, OptionValue]) -> StrategyResult:
        """Run on every snapshot of `scenario` with the full, checked `options`; the result
        is named `label`."""
        from opfbench.scenario import Scenario

        if not isinstance(scenario, Scenario):
            raise InputError(
                f"strategy {label!r} runs on a Scenario (e.g. Scenario.snapshot(net)), got {type(scenario).__name__}"
            )
        if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, float, np.number, np.ndarray)):
            raise InputError(f"reserve coefficient k must be a number in [0, 1], got {k!r}")
        result = self.runner(scenario, k, **(options | self.fixed))
        return result if result.strategy == label else dataclasses.replace(result, strategy=label)


@dataclass(frozen=True)
class ModelSpec:
    """One registered formulation model (`formulations.model` says what a model is):
    `build(net, slack_export)` makes it for one network; `role` says what its objective
    is (`MEANING`); `networks` the network classes it models; `serves_problem`: it is a
    candidate for the OPF problem's model of its role (the `acopf` / `socp` strategies,
    the lowest `preference` among those that model the network), else it is a strategy of
    its own under its name."""

    name: str
    role: Role
    build: Callable[[Network | PhaseNetwork, bool], Any]
    summary: str
    networks: tuple[str, ...] = SUPPORTS
    serves_problem: bool = False
    preference: int = 0
    source: str = OPFBENCH

    @property
    def meaning(self) -> str:
        return MEANING[self.role]

    def models(self, net: Network | PhaseNetwork) -> bool:
        return network_class(net) in self.networks


STRATEGIES: dict[str, StrategySpec] = PROCESS.table("strategies")
"""Every registered strategy by name, in registration order (`catalog.specs` orders them)."""
MODELS: dict[str, ModelSpec] = PROCESS.table("formulation models")
"""Every registered formulation model by name."""


def _check_name(what: str, name: str, source: str, held: StrategySpec | ModelSpec | None) -> None:
    if not _NAME.match(name):
        raise InputError(f"{source}: {what} name {name!r} must be lower-case letters, digits, '.', '_', '+' or '-'")
    if held is not None and held.source != source:
        raise InputError(f"{source}: {what} name {name!r} is taken (by {held.source})")
    if held is not None:  # one source, one entry a name: the second would silently replace the first
        raise InputError(f"{what} {name!r} is registered twice by {source}: give each its own name")


RUNNER_ARGUMENTS = ("scenario", "k")
"""What `StrategySpec.runner(scenario, k, **options)` takes itself: no option's name."""


def register(spec: StrategySpec) -> None:
    """Add a strategy; InputError for a name that is taken (by another source, or already
    by this one) or not a valid name (lower-case letters, digits, '.', '_', '+', '-'), or
    an option named like the runner's own arguments (`RUNNER_ARGUMENTS`)."""
    _check_name("strategy", spec.name, spec.source, STRATEGIES.get(spec.name))
    for option in spec.options:
        if option.name in RUNNER_ARGUMENTS:
            raise InputError(
                f"{spec.source}: strategy {spec.name!r}: option name {option.name!r} is the runner's own argument "
                f"({', '.join(RUNNER_ARGUMENTS)}: the snapshots and the reserve); give the option another name"
            )
    STRATEGIES[spec.name] = spec


def register_model(model: ModelSpec) -> None:
    """Add a formulation model (the same rules for its name as `register`)."""
    _check_name("formulation model", model.name, model.source, MODELS.get(model.name))
    MODELS[model.name] = model


def forget_source(source: str) -> None:
    """Remove every strategy and model that `source` registered (a plugin unloaded, or one
    that failed half-way)."""
    for table in (STRATEGIES, MODELS):
        for name in [n for n, entry in table.items() if entry.source == source]:
            del table[name]


_loading: list[str] = []


@contextmanager
def loading(ref: str) -> Iterator[None]:
    """While a plugin `ref` loads, what its decorators register is registered under it."""
    _loading.append(ref)
    try:
        yield
    finally:
        _loading.pop()


def source_of(module: str) -> str:
    """The source an entry declared in `module` is registered under: the plugin loading now,
    else "opfbench" for opfbench's own modules, else the module's name."""
    if _loading:
        return _loading[-1]
    return OPFBENCH if module == OPFBENCH or module.startswith(OPFBENCH + ".") else module


def strategy(
    name: str,
    *,
    kind: Kind,
    summary: str,
    options: tuple[Option, ...] = (),
    fixed: Mapping[str, object] | None = None,
    reads: tuple[str, ...] = (),
    uses_forecast: bool = False,
    bound_rank: int | None = None,
    role: Role | None = None,
    supports: tuple[str, ...] = SUPPORTS,
    network_check: Callable[[Network], None] | None = None,
    check: Callable[[dict], None] | None = None,
    columns: Mapping[str, str] | None = None,
    snapshot_wise: bool = False,
) -> Callable[[Runner], Runner]:
    """Register the decorated `runner(scenario, k, **options) -> StrategyResult` as the
    strategy `name` (fields: `StrategySpec`). Stacked, one runner serves several entries
    (e.g. the AC OPF with the paper's options `fixed`)."""

    def decorate(runner: Runner) -> Runner:
        register(
            StrategySpec(
                name,
                kind,
                summary,
                runner,
                reads=reads,
                options=options,
                fixed=dict(fixed or {}),
                uses_forecast=uses_forecast,
                bound_rank=bound_rank,
                role=role,
                supports=supports,
                network_check=network_check,
                check=check,
                columns=dict(columns or {}),
                snapshot_wise=snapshot_wise,
                source=source_of(runner.__module__),
                module=runner.__module__,
            )
        )
        return runner

    return decorate
