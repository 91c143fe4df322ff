"""Every strategy described once, and the only list of them: its kind (local rule or
centralized formulation), how it runs, its typed options, whether it reads a forecast
(Algorithm 3's limit), whether it gives a certified lower bound, which networks it
supports, what it measures and the extra result columns it adds. Plugins add entries
(`opfbench.plugins`); nothing else names strategies.

A configuration is a strategy with options, written as a label `NAME:key=value,…`
(`volt-var:curve=a`, `acopf:fallback=paper`). `configuration(label)` parses and checks
it; its canonical label — options in declaration order, defaults dropped, numbers
written back exactly — names it in every table, the manifest and the report, so
`volt-var`, `volt-var:curve=b` and `volt-var:curve=b,` are one configuration.

A strategy runs either through a runner `run(scenario, k, **options) -> StrategyResult`
(`runner`: "module:function"), or — local rules — as a target of the local-rule engine
(`rule`: "module:function" or a function, `target(m, **options) -> (S, n_der)` MVAr; the
engine clips it to the limits and settles rules that read |V| or flows; see
`opfbench.strategies.engine`). An entry may pin options of its runner (`fixed`):
`acopf-paper` is the AC OPF under the paper's setup, a configuration of its own. An
option may take its default from a run-level setting (`Option.setting`, e.g. the AC OPF
solver of `opfbench run --acopf-solver`), applied by `Configuration.run(settings=…)`
where the label does not set it.

A learned strategy (`fit`: "module:function") is a local rule fitted to the reference
optimum over a training period: its options `train` (the period, fitted by `opfbench run`)
and `params` (a fitted rule's file) say where its parameters come from, so it has no
default configuration and is not part of `DEFAULT_RUN`.
"""

from __future__ import annotations

import dataclasses
import difflib
import importlib
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from opfbench.errors import InputError
from opfbench.formulations.options import ACOPF_SOLVERS, FALLBACKS
from opfbench.strategies.learned import KNOTS, RHO
from opfbench.strategies.rules import DEFAULT_SETTLING as SETTLING
from opfbench.strategies.rules import READS, RESIDUAL, Rule

if TYPE_CHECKING:
    from opfbench.result import StrategyResult
    from opfbench.scenario import Scenario

Kind = Literal["local", "formulation"]
SUPPORTS = ("radial", "meshed")
_NAME = re.compile(r"^[a-z0-9][a-z0-9._-]*$")
_DECIMAL = re.compile(r"^[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?$", re.ASCII)
OptionValue = bool | int | float | str | tuple[float, ...]


@dataclass(frozen=True)
class Option:
    """A typed option. Its type is its default's: bool (true/false), int, float (a decimal
    number), str (one of `choices`) or a tuple of floats (written `0.9/1.0/1.1`);
    `check(value)` returns a problem (text) or None; `setting` names the run-level setting
    that supplies the default where a label does not set the option."""

    name: str
    default: OptionValue
    help: str
    choices: tuple[str, ...] = ()
    check: Callable[[OptionValue], str | None] | None = None
    setting: str | None = None

    @property
    def type_name(self) -> str:
        if isinstance(self.default, bool):
            return "bool"
        if isinstance(self.default, tuple):
            return "numbers"
        return {int: "int", float: "number", str: "choice" if self.choices else "text"}[type(self.default)]

    def parse(self, text: str) -> OptionValue:
        """The value written `text` in a label; InputError (without the context) otherwise."""
        kind = self.type_name
        if kind == "bool":
            if text.lower() not in ("true", "false"):
                raise InputError(f"{text!r} is not true or false")
            return text.lower() == "true"
        if kind == "int":
            if not re.fullmatch(r"[+-]?\d+", text):
                raise InputError(f"{text!r} is not a whole number")
            return int(text)
        if kind == "number":
            return _decimal(text)
        if kind == "numbers":
            return tuple(_decimal(part) for part in text.split("/")) if text else ()
        return text

    def coerce(self, value: object) -> OptionValue:
        """`value` as this option's type (an int for a float option is a float); InputError
        for another type (a text 'false' is no False)."""
        kind = self.type_name
        if isinstance(value, (bool, np.bool_)):
            if kind == "bool":
                return bool(value)
        elif kind == "int" and isinstance(value, (int, np.integer)):
            return int(value)
        elif kind == "number" and isinstance(value, (int, float, np.integer, np.floating)):
            return float(value)
        elif kind == "numbers" and isinstance(value, (tuple, list)) and all(_is_number(v) for v in value):
            return tuple(float(v) for v in value)
        elif kind in ("choice", "text") and isinstance(value, str):
            return value
        raise InputError(f"{value!r} is not a {kind} like its default {self.format(self.default)!r}")

    def validate(self, value: OptionValue) -> None:
        """InputError (without the context) unless `value` is allowed."""
        if isinstance(value, float) and not math.isfinite(value):
            raise InputError(f"{value} is not finite")
        if isinstance(value, tuple) and not all(math.isfinite(v) for v in value):
            raise InputError(f"{self.format(value)} has a value that is not finite")
        if self.choices and value not in self.choices:
            raise InputError(f"{value!r} is not one of {', '.join(self.choices)}")
        problem = self.check(value) if self.check is not None else None
        if problem:
            raise InputError(problem)

    def format(self, value: OptionValue) -> str:
        """`value` as written in a canonical label (numbers exactly: repr, no trailing .0)."""
        if isinstance(value, bool):
            return "true" if value else "false"
        if isinstance(value, float):
            return _number_text(value)
        if isinstance(value, tuple):
            return "/".join(_number_text(v) for v in value)
        return str(value)

    def describe(self) -> dict:
        """The option as `opfbench strategies --json` lists it."""
        out: dict[str, object] = {
            "name": self.name,
            "type": self.type_name,
            "default": self.format(self.default),
            "help": self.help,
        }
        if self.choices:
            out["allowed"] = list(self.choices)
        if self.setting:
            out["default_from"] = self.setting
        return out


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def _decimal(text: str) -> float:
    if not _DECIMAL.match(text):
        raise InputError(f"{text!r} is not a decimal number")
    value = float(text)
    if not math.isfinite(value):
        raise InputError(f"{text!r} is not finite")
    return value


def _number_text(value: float) -> str:
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def _positive(value: OptionValue) -> str | None:
    return None if isinstance(value, (int, float)) and value > 0 else f"must be > 0, got {value}"


def _step(value: OptionValue) -> str | None:
    return None if isinstance(value, float) and 0 < value <= 1 else f"a step factor lies in (0, 1], got {value}"


def _non_negative(value: OptionValue) -> str | None:
    return None if isinstance(value, int) and value >= 0 else f"must be ≥ 0, got {value}"


SAFE = Option("safe", False, "Algorithm 3: cap the forecast-aware limit at the physical capability at P^C")
#: The closed-loop engine's options (`strategies.engine.Settling`), on every rule that reads |V| or flows.
SETTLING_OPTIONS = (
    Option("max_steps", SETTLING.max_steps, "damped steps before a snapshot counts as not-settled", check=_non_negative),
    Option("tol_v_pu", SETTLING.tol_v_pu, "settled: largest bus-voltage change of the last step ≤ this, p.u.", check=_positive),
    Option("tol_q_mvar", SETTLING.tol_q_mvar, "settled: largest change the rule still asks ≤ this, MVAr", check=_positive),
    Option("step_factor", SETTLING.step_factor, "damping α of Q += α·(target − Q), the first step's when adaptive", check=_step),
    Option("adaptive", SETTLING.adaptive, "adapt α per DER from successive voltage changes (OpenDSS InvControl)"),
)
_ENGINE = {o.name for o in (SAFE, *SETTLING_OPTIONS)}
#: A learned strategy's options (`StrategySpec.fit`): where its parameters come from, and the fit's.
TRAIN = Option("train", "", "training period START..END (END excluded): opfbench run fits the rule to the AC OPF over it")
PARAMS = Option("params", "", "a fitted rule's parameters (JSON: a run folder's learned/*.json)")


def _rho(value: OptionValue) -> str | None:
    return None if isinstance(value, float) and 0 < value < 1 else f"a contraction factor lies in (0, 1), got {value}"


def _rounds(value: OptionValue) -> str | None:
    return None if isinstance(value, int) and 0 <= value <= 20 else f"rounds lie in 0..20, got {value}"


LEARNED_OPTIONS = (
    TRAIN,
    PARAMS,
    Option("rho", RHO, "the slope bound's contraction factor ρ: |∂Q_i/∂|V_i|| ≤ ρ / Σ_j |∂|V_i|/∂Q_j|", check=_rho),
    Option(
        "rounds",
        0,
        "end-to-end rounds: refit on the voltages the rule produces in closed loop on the training period",
        check=_rounds,
    ),
)
_SETTLING_FIELD = {"tol_v_pu": "tol_v_pu", "tol_q_mvar": "tol_q_mvar", "max_steps": "max_steps", "step_factor": "step_factor"}
CLOSED_LOOP_COLUMNS = {RESIDUAL: "largest |clip(target) − Q| at the last iterate, MVAr (≤ tol_q_mvar when settled)"}


def _callable(target: str | Callable) -> Callable:
    if callable(target):
        return target
    module, func = target.split(":")
    return getattr(importlib.import_module(module), func)


@dataclass(frozen=True)
class StrategySpec:
    """One registered strategy (see the module docstring). `reads`: what a local rule
    measures (`strategies.engine.READS`); `bound_rank`: it gives a certified lower bound on
    the losses (the summary takes the bound from the lowest rank present); `supports`:
    network classes it runs on ("radial", "meshed"); `fit`: "module:function",
    `fit(name, training, options) -> fitted parameters`, for a learned strategy (module
    docstring); `network_check`: "module:function"
    refusing a network it cannot model, before any work; `check`: refuses option
    combinations (a function of the options dict); `columns`: extra per-step result
    columns (name → meaning, from `StrategyResult.extra`); `relaxation`: its point is a
    relaxation's (evaluated by AC power flow), never a certified AC optimum; `source`:
    "opfbench" or the plugin that registered it."""

    name: str
    kind: Kind
    summary: str
    runner: str | Callable | None = None
    rule: str | Callable | None = None
    reads: tuple[str, ...] = ()
    options: tuple[Option, ...] = ()
    fixed: dict[str, object] = field(default_factory=dict)
    uses_forecast: bool = False
    bound_rank: int | None = None
    supports: tuple[str, ...] = SUPPORTS
    network_check: str | None = None
    check: str | Callable[[dict], None] | None = None
    columns: dict[str, str] = field(default_factory=dict)
    relaxation: bool = False
    source: str = "opfbench"
    fit: str | Callable | None = None
    snapshot_wise: bool = False

    def __post_init__(self) -> None:
        if (self.runner is None) == (self.rule is None):
            raise InputError(f"strategy {self.name!r}: give a runner or a rule, not both or neither")
        unknown = set(self.reads) - set(READS)
        if unknown:
            raise InputError(
                f"strategy {self.name!r}: unknown measurement(s) {', '.join(sorted(unknown))}; it may read {', '.join(READS)}"
            )

    @property
    def option(self) -> dict[str, Option]:
        return {o.name: o for o in self.options}

    @property
    def closed_loop(self) -> bool:
        return self.rule is not None and bool({"v", "flows"} & set(self.reads))

    @property
    def learned(self) -> bool:
        """Fitted to the reference optimum: its parameters come from `train` or `params`."""
        return self.fit is not None

    def fitted_options(self, ref: str) -> dict[str, OptionValue]:
        """The options that run a learned configuration with the fitted parameters `ref`:
        params=ref, and the fit's own options (train, rho, …) at their defaults — the fit
        used them; the engine's options stay the label's."""
        return {o.name: o.default for o in self.options if o.name not in _ENGINE} | {"params": ref}

    def fit_rule(self, training: Any, options: Mapping[str, OptionValue]) -> Any:
        """A learned strategy's fitted parameters for `training` (`fit`)."""
        assert self.fit is not None, f"{self.name} is not a learned strategy"
        return _callable(self.fit)(self.name, training, dict(options))

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
            _callable(self.check)(options)

    def check_network(self, net) -> None:
        """InputError / NetworkError for a network this strategy cannot run on."""
        kind = "meshed" if net.meshed else "radial"
        if kind not in self.supports:
            raise InputError(f"strategy {self.name!r} runs on {', '.join(self.supports)} networks; {net.name} is {kind}")
        if self.network_check is not None:
            _callable(self.network_check)(net)

    def describe(self) -> dict:
        """The entry as `opfbench strategies --json` lists it."""
        return {
            "name": self.name,
            "kind": self.kind,
            "summary": self.summary,
            "reads": list(self.reads) if self.kind == "local" else ["the whole network (centralized)"],
            "closed_loop": self.closed_loop,
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
        if self.rule is not None:
            from opfbench.strategies.engine import run_rule

            engine = {key: v for key, v in options.items() if key in _ENGINE}
            changes: dict[str, Any] = {key: v for key, v in engine.items() if key != "safe"}
            settling = dataclasses.replace(SETTLING, **changes)
            rule = Rule(self.name, _callable(self.rule), frozenset(self.reads))
            rule_options = {key: v for key, v in options.items() if key not in _ENGINE}
            result = run_rule(label, rule, scenario, k, rule_options, safe=bool(engine.get("safe", False)), settling=settling)
        else:
            assert self.runner is not None
            result = _callable(self.runner)(scenario, k, **(options | self.fixed))
        return result if result.strategy == label else dataclasses.replace(result, strategy=label)


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


def _builtin() -> tuple[StrategySpec, ...]:
    closed_loop = (SAFE, *SETTLING_OPTIONS)
    solver = Option(
        "solver",
        "auto",
        "auto: the SOCP certifies the AC optimum where it can, IPOPT solves the rest; ipopt: IPOPT on every step",
        choices=ACOPF_SOLVERS,
        setting="acopf_solver",
    )
    slack_export = Option("slack_export", True, "the slack may export (reverse power flow); false: slack P ≥ 0")
    curve = Option("curve", "b", "IEEE 1547-2018 category: a or b", choices=("a", "b"))

    def points(x: str, help_x: str) -> tuple[Option, Option]:
        return (
            Option(x, (), f"explicit curve points instead of a preset: {help_x}, increasing, written 0.9/1.0/1.1 (with q=)"),
            Option("q", (), "explicit curve points: Q per unit, one per point, written 0.44/0/-0.44"),
        )

    std = "opfbench.strategies.standards"
    paper = "opfbench.strategies.paper"
    learned = "opfbench.strategies.learned"

    def learned_rule(name: str, summary: str, family: str, reads: tuple[str, ...], *extra: Option) -> StrategySpec:
        """A learned family (`strategies.learned`): slope-bounded, closed loop."""
        return StrategySpec(
            name,
            "local",
            summary + " (slope-bounded), closed loop",
            rule=f"{learned}:{family}_target",
            reads=reads,
            options=(*LEARNED_OPTIONS, *extra, *closed_loop),
            uses_forecast=True,
            check=f"{learned}:check_{family}",
            columns=CLOSED_LOOP_COLUMNS,
            fit=f"{learned}:fit_configuration",
            snapshot_wise=True,
        )

    check = "opfbench.formulations.problem:check_supported"
    return (
        StrategySpec("no-action", "local", "every DER at Q = 0", rule=f"{paper}:no_action_target", snapshot_wise=True),
        StrategySpec(
            "llma",
            "local",
            "Algorithm 1: Q = the load's Q at the DER's own bus, within (1 − k)·Qmax",
            rule=f"{paper}:llma_target",
            reads=("load",),
            options=(SAFE,),
            uses_forecast=True,
            snapshot_wise=True,
        ),
        StrategySpec(
            "lfma",
            "local",
            "Algorithm 2: LLMA plus the measured upstream Q inflow, sign-change rules",
            runner=f"{paper}:lfma",
            reads=("load", "flows"),
            options=(SAFE,),
            uses_forecast=True,
            snapshot_wise=True,
        ),
        StrategySpec(
            "volt-var",
            "local",
            "IEEE 1547-2018 Volt-VAR Q(V) in p.u. of S̄ (B: 0.92/+0.44 0.98/0 1.02/0 1.08/−0.44; "
            "A: 0.90/+0.25 1.00/0 1.10/−0.25), closed loop",
            rule=f"{std}:volt_var",
            reads=("v",),
            options=(curve, *points("v", "|V| p.u."), *closed_loop),
            uses_forecast=True,
            check=f"{std}:check_volt_var",
            columns=CLOSED_LOOP_COLUMNS,
            snapshot_wise=True,
        ),
        StrategySpec(
            "watt-var",
            "local",
            "IEEE 1547-2018 Watt-VAR Q(P/P̄) in p.u. of S̄ (0.2/0 0.5/0 1.0/−0.44 for B, −0.25 for A)",
            rule=f"{std}:watt_var",
            reads=("p",),
            options=(curve, *points("p", "P/P̄"), SAFE),
            uses_forecast=True,
            check=f"{std}:check_watt_var",
            snapshot_wise=True,
        ),
        StrategySpec(
            "const-pf",
            "local",
            "constant power factor: Q = ∓|P|·tan(acos pf)",
            rule=f"{std}:const_pf",
            reads=("p",),
            options=(
                Option("pf", 0.95, "power factor in (0, 1]"),
                Option("mode", "absorb", "absorb (under-excited) or inject (over-excited)", choices=("absorb", "inject")),
                SAFE,
            ),
            uses_forecast=True,
            check=f"{std}:check_const_pf",
            snapshot_wise=True,
        ),
        StrategySpec(
            "cosphi-p",
            "local",
            "VDE-AR-N 4105 cos φ(P): 1 up to P/P̄ = 0.5, then linear to 0.90 under-excited at P̄",
            rule=f"{std}:cosphi_p",
            reads=("p",),
            options=(
                Option("pf_min", 0.90, "cos φ at P̄, under-excited (0.95 for units ≤ 4.6 kVA)"),
                Option("p_start", 0.5, "P/P̄ where cos φ leaves 1"),
                SAFE,
            ),
            uses_forecast=True,
            check=f"{std}:check_cosphi_p",
            snapshot_wise=True,
        ),
        StrategySpec(
            "q-u",
            "local",
            "VDE-AR-N 4110 Q(U): 0.96/+0.33 to 1.04/−0.33 p.u. of P̄ (dead band: 0.94/0.96/1.04/1.06), closed loop",
            rule=f"{std}:q_u",
            reads=("v",),
            options=(
                Option("deadband", False, "the characteristic with its dead band 0.96–1.04 p.u."),
                Option("q_max", 0.33, "Q at the characteristic's ends, p.u. of P̄"),
                *points("v", "|V| p.u."),
                *closed_loop,
            ),
            uses_forecast=True,
            check=f"{std}:check_q_u",
            columns=CLOSED_LOOP_COLUMNS,
            snapshot_wise=True,
        ),
        learned_rule(
            "learned-affine",
            "learned linear decision rule Q/S̄ = a + b·P/S̄ + c·|V| + d·Q_load/S̄ per DER (c ≤ 0), fitted to the AC OPF",
            "affine",
            ("v", "p", "load"),
        ),
        learned_rule(
            "learned-vv",
            "learned Volt-VAR: monotone piecewise-linear Q(|V|) per DER, knots at training-voltage quantiles, fitted to the AC OPF",
            "vv",
            ("v",),
            Option("knots", KNOTS, "knots of the curve, at quantiles of the DER's training voltages"),
        ),
        learned_rule(
            "learned-1547",
            "learned IEEE 1547 Volt-VAR: the four-point shape with per-DER points fitted to the AC OPF",
            "ieee1547",
            ("v",),
        ),
        StrategySpec(
            "acopf",
            "formulation",
            "centralized AC OPF (IPOPT), fallback chain ending at an AC-feasible point",
            runner="opfbench.formulations.acopf:run_acopf",
            options=(
                Option("fallback", "chain", "chain: warm → cold IPOPT → SOCP → no action; paper: no action", choices=FALLBACKS),
                slack_export,
                solver,
            ),
            bound_rank=1,
            network_check=check,
        ),
        StrategySpec(
            "acopf-paper",
            "formulation",
            "AC OPF under the paper's setup: slack may not export, failure → no action",
            runner="opfbench.formulations.acopf:run_acopf",
            options=(solver,),
            fixed={"fallback": "paper", "slack_export": False},
            network_check=check,
        ),
        StrategySpec(
            "socp",
            "formulation",
            "SOCP relaxation (Clarabel): certified lower bound; its Q evaluated by AC power flow",
            runner="opfbench.formulations.socp:run_socp",
            options=(slack_export,),
            bound_rank=0,
            network_check=check,
            relaxation=True,
            snapshot_wise=True,
        ),
    )


STRATEGIES: dict[str, StrategySpec] = {s.name: s for s in _builtin()}
"""Every registered strategy by name: the built-in ones, then the plugins' (`register`)."""
#: The reference configurations every comparison is made against: the baseline (every DER
#: at Q = 0) and the optimum whose loss reduction the others' shares are measured by.
BASELINE = "no-action"
REFERENCE_OPTIMUM = "acopf"
#: The paper's own configurations, which its claims are about (`report.claims`): its local
#: rules (LLMA, LFMA) and its OPF setup.
PAPER_RULES = ("llma", "lfma")
PAPER_OPF = "acopf-paper"
#: `opfbench run`'s default grid: every built-in strategy at its default options (the
#: learned ones have none: their parameters come from a training period or a file).
DEFAULT_RUN = tuple(name for name, s in STRATEGIES.items() if not s.learned)
#: The default grid's strategies under a forecast source: the paper's Algorithm 3 rules
#: (the grid codes' rules know no forecast; only Algorithm 3's limit would change them).
DEFAULT_FORECAST = PAPER_RULES
#: `opfbench fault`'s default strategies: the baseline, the paper's rules, the grid code's
#: Volt-VAR and the optimum.
DEFAULT_FAULT = (BASELINE, "llma", "lfma", "volt-var", REFERENCE_OPTIMUM)


def register(spec: StrategySpec) -> None:
    """Add a plugin's strategy; InputError for a name that is taken by another source or
    not a valid name (lower-case letters, digits, '.', '_', '-')."""
    if not _NAME.match(spec.name):
        raise InputError(f"{spec.source}: strategy name {spec.name!r} must be lower-case letters, digits, '.', '_' or '-'")
    held = STRATEGIES.get(spec.name)
    if held is not None and held.source != spec.source:
        raise InputError(f"{spec.source}: strategy name {spec.name!r} is taken (by {held.source})")
    STRATEGIES[spec.name] = spec


def spec(name: str) -> StrategySpec:
    """The entry `name` (a plugin of the `opfbench.strategies` entry-point group is loaded
    on first need); InputError naming the closest names for an unknown one."""
    if name not in STRATEGIES:
        from opfbench.plugins import load_entry_points

        load_entry_points()
    if name not in STRATEGIES:
        close = difflib.get_close_matches(name, list(STRATEGIES), n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise InputError(f"unknown strategy {name!r}{hint}; choose from {', '.join(STRATEGIES)} (or load a plugin: --plugin)")
    return STRATEGIES[name]


def specs() -> tuple[StrategySpec, ...]:
    """Every registered entry, entry-point plugins included, in registration order."""
    from opfbench.plugins import load_entry_points

    load_entry_points()
    return tuple(STRATEGIES.values())


def configuration(label: str) -> Configuration:
    """The configuration a label `NAME[:key=value,…]` means, checked: InputError naming the
    label and what is wrong (unknown strategy or option, a value not of the option's type
    or not allowed, an option given twice, a combination the strategy refuses)."""
    if not isinstance(label, str):
        raise InputError(f"a strategy label is text like lfma or volt-var:curve=a, got {type(label).__name__}")
    name, _, rest = label.strip().partition(":")
    entry = spec(name)
    given: dict[str, OptionValue] = {}
    known = entry.option
    for item in (part.strip() for part in rest.split(",")) if rest else ():
        if not item:
            continue
        key, eq, text = item.partition("=")
        key, text = key.strip(), text.strip()
        if not eq or not key:
            raise InputError(f"strategy label {label!r}: {item!r} is not key=value")
        if key in given:
            raise InputError(f"strategy label {label!r}: option {key} given twice")
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
    name = str(label).partition(":")[0]
    return STRATEGIES.get(name)


def is_formulation(label: str) -> bool:
    """The label's strategy is a registered formulation (an unknown one — a plugin's — is a local rule)."""
    spec = describe(label)
    return spec is not None and spec.kind == "formulation"


def is_relaxation(label: str) -> bool:
    """The label's strategy is a relaxation: its point is the bound's, not a certified AC optimum."""
    spec = describe(label)
    return spec is not None and spec.relaxation


def rank(label: str) -> int:
    """Registry order of a label's strategy (for sorting tables); unknown names last."""
    names = list(STRATEGIES)
    name = str(label).partition(":")[0]
    return names.index(name) if name in names else len(names)
