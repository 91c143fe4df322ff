"""Every strategy by name, its configurations and the reference configurations — what the
rest of opfbench asks the registry.

The entries are registered by the modules that define them (`registry.specs`): the built-in
local rules when this module is imported, the built-in formulations (the OPF problem's
strategies and every model under `formulations/models/`) on first need, plugins of the
`opfbench.strategies` entry-point group when a name is not known or every strategy is
listed (`opfbench.plugins`). `specs()` lists them in a stable order: the built-ins in the
order of `BUILT_IN` (then the formulation models, by module name), then the plugins in
the order they loaded.

A configuration is a strategy with options, written as a label `NAME:key=value,…`
(`volt-var:curve=a`, `acopf:fallback=paper`). `configuration(label)` parses and checks
it; its canonical label — options in declaration order, defaults dropped, numbers
written back exactly — names it in every table, the manifest and the report, so
`volt-var`, `volt-var:curve=b` and `volt-var:curve=b,` are one configuration. An entry
may pin options of its runner (`fixed`): `acopf-paper` is the AC OPF under the paper's
setup, a configuration of its own. An option may take its default from a run-level
setting (`Option.setting`, e.g. the AC OPF solver of `opfbench run --acopf-solver`),
applied by `Configuration.run(settings=…)` where the label does not set it.

A learned strategy (`StrategySpec.fit`) is a local rule fitted to the reference optimum
over a training period: its options `train` (the period, fitted by `opfbench run`) and
`params` (a fitted rule's file) say where its parameters come from, so it has no default
configuration and is not part of `references.DEFAULT_RUN`.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from opfbench.errors import InputError
from opfbench.registry.options import OptionValue
from opfbench.registry.specs import OPFBENCH, STRATEGIES, Kind, StrategySpec

if TYPE_CHECKING:
    from opfbench.result import StrategyResult
    from opfbench.scenario import Scenario

#: The modules of the built-in strategies, in the order every listing and table shows them.
BUILT_IN = (
    "opfbench.strategies.paper",
    "opfbench.strategies.standards",
    "opfbench.learned.rules",
    "opfbench.formulations.opf_strategies",
)


def _load_rules() -> None:
    """Register the built-in local rules (imported on first need: this module stays light
    for the CLI's parser)."""
    from opfbench.learned import rules as learned
    from opfbench.strategies import paper, standards

    assert {paper.__name__, standards.__name__, learned.__name__} <= set(BUILT_IN)


def _load_formulations() -> None:
    """Register the built-in formulations (the OPF problem's strategies and every model
    module): imported on first need, as they load cvxpy, Clarabel and CasADi."""
    from opfbench.formulations import opf_strategies as opf
    from opfbench.formulations.model import load_models

    assert opf.__name__ in BUILT_IN
    load_models()


def _load_entry_points() -> None:
    from opfbench.plugins import load_entry_points

    load_entry_points()


def _order(spec: StrategySpec) -> tuple[int, int, str]:
    """Built-ins in `BUILT_IN`'s order (the models' after them, by module), plugins last."""
    if spec.source != OPFBENCH:
        return (2, 0, "")
    return (0, BUILT_IN.index(spec.module), "") if spec.module in BUILT_IN else (1, 0, spec.module)


def _known(name: str) -> StrategySpec | None:
    """The entry `name` among opfbench's own (loaded on need) and the plugins loaded so far."""
    _load_rules()
    if name not in STRATEGIES:
        _load_formulations()
    return STRATEGIES.get(name)


def spec(name: str) -> StrategySpec:
    """The entry `name` (a plugin of the `opfbench.strategies` entry-point group is loaded
    on first need); InputError naming the closest names for an unknown one."""
    if _known(name) is None:
        _load_entry_points()
    if name not in STRATEGIES:
        close = difflib.get_close_matches(name, list(STRATEGIES), n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        names = ", ".join(s.name for s in specs())
        raise InputError(f"unknown strategy {name!r}{hint}; choose from {names} (or load a plugin: --plugin)")
    return STRATEGIES[name]


def specs() -> tuple[StrategySpec, ...]:
    """Every registered entry, entry-point plugins included, in the catalog's order (module
    docstring)."""
    _load_rules()
    _load_formulations()
    _load_entry_points()
    entries = list(STRATEGIES.values())
    return tuple(sorted(entries, key=lambda s: (*_order(s), entries.index(s))))


@dataclass(frozen=True)
class Configuration:
    """A strategy with the options its label sets (`given`, typed, defaults left out)."""

    spec: StrategySpec
    given: dict[str, OptionValue]

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def label(self) -> str:
        """The canonical label: NAME, or NAME:key=value,… in declaration order, defaults dropped
        (except for options whose default a run-level setting supplies)."""
        parts = [f"{o.name}={o.format(self.given[o.name])}" for o in self.spec.options if o.name in self.given]
        return self.name + (":" + ",".join(parts) if parts else "")

    @property
    def kind(self) -> Kind:
        return self.spec.kind

    @property
    def uses_forecast(self) -> bool:
        return self.spec.uses_forecast

    @property
    def curtails(self) -> bool:
        """Its DER may deliver less active power than they have: a rule that caps it, any
        rule with reactive priority (`priority=q`), the AC OPF with `curtail=true`."""
        options = self.options()
        return self.spec.curtails or options.get("priority") == "q" or options.get("curtail") is True

    def options(self, settings: Mapping[str, object] | None = None) -> dict[str, OptionValue]:
        """Every option's value: the label's, else the run-level setting the option names,
        else its default."""
        out = self.spec.defaults()
        for o in self.spec.options:
            if o.setting is not None and settings is not None and o.setting in settings and o.name not in self.given:
                out[o.name] = self.spec.resolve({o.name: settings[o.setting]})[o.name]
        return out | self.given

    def run(self, scenario: Scenario, k: float, settings: Mapping[str, object] | None = None, **overrides) -> StrategyResult:
        """Run on every snapshot of `scenario` (options: the label's, the run-level
        `settings`, then `overrides` by name); the result is named by the label."""
        options = self.options(settings) | self.spec.resolve(overrides)
        self.spec.check_options(options)
        return self.spec.run(scenario, k, self.label, options)


def configuration(label: str) -> Configuration:
    """The configuration a label `NAME[:key=value,…]` means, checked: InputError naming the
    label and what is wrong (unknown strategy or option, a value not of the option's type
    or not allowed, an option given twice, a combination the strategy refuses)."""
    if not isinstance(label, str):
        raise InputError(f"a strategy label is text like lfma or volt-var:curve=a, got {type(label).__name__}")
    name, _, rest = label.strip().partition(":")
    entry = spec(name)
    given: dict[str, OptionValue] = {}
    seen: set[str] = set()  # a value equal to the default is not kept, but it was given
    known = entry.option
    for item in (part.strip() for part in rest.split(",")) if rest else ():
        if not item:
            continue
        key, eq, text = item.partition("=")
        key, text = key.strip(), text.strip()
        if not eq or not key:
            raise InputError(f"strategy label {label!r}: {item!r} is not key=value")
        if key in seen:
            raise InputError(f"strategy label {label!r}: option {key} given twice; give it once")
        seen.add(key)
        if key not in known:
            raise InputError(f"strategy label {label!r}: {name} takes no option {key} (options: {', '.join(known) or 'none'})")
        try:
            value = known[key].parse(text)
            known[key].validate(value)
        except InputError as exc:
            raise InputError(f"strategy label {label!r}: option {key}: {exc}") from None
        if value != known[key].default or known[key].setting is not None:  # a run-level setting may change the default
            given[key] = value
    config = Configuration(entry, {o.name: given[o.name] for o in entry.options if o.name in given})
    try:
        entry.check_options(config.options())
    except InputError as exc:
        raise InputError(f"strategy label {label!r}: {exc}") from None
    return config


def canonical(label: str) -> str:
    """The canonical label of `label` (see `configuration`)."""
    return configuration(label).label


def get_strategy(label: str) -> Configuration:
    """The configuration of `label` (a bare name is the strategy at its defaults)."""
    return configuration(label)


def run_strategy(
    label: str, scenario: Scenario, k: float, settings: Mapping[str, object] | None = None, **options
) -> StrategyResult:
    """Run the configuration `label` on every snapshot of `scenario` at reserve k; `options`
    (Python values, by name) override the label's; `settings` are run-level settings
    (`Option.setting`). The result is named by the canonical label."""
    return configuration(label).run(scenario, k, settings, **options)


def describe(label: str) -> StrategySpec | None:
    """The entry of a label's strategy, or None when no registered strategy has its name
    (e.g. a plugin's, read back from a run folder without the plugin loaded)."""
    return _known(str(label).partition(":")[0])


def is_formulation(label: str) -> bool:
    """The label's strategy is a registered formulation (an unknown one — a plugin's — is a local rule)."""
    spec = describe(label)
    return spec is not None and spec.kind == "formulation"


def is_relaxation(label: str) -> bool:
    """The label's strategy is a relaxation: its point is the bound's, not a certified AC optimum."""
    spec = describe(label)
    return spec is not None and spec.role == "relaxation"


def rank(label: str) -> int:
    """Catalog order of a label's strategy (for sorting tables); unknown names last."""
    names = [s.name for s in specs()]
    name = str(label).partition(":")[0]
    return names.index(name) if name in names else len(names)
