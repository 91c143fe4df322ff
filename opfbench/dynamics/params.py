"""Parameters of the RMS fault model (paper §IV; see the README's fault study). Every default is the reference
scenario; every field is an option. Per unit on the case's MVA base unless stated.

Sources:
- Induction motor data: Kundur, *Power System Stability and Control* (1994), §7.2.3,
  Table 7.2 "typical small industrial motor": Rs 0.031, Xs 0.10, Xm 3.2, Rr 0.018,
  Xr 0.18 p.u. on the motor base; third-order model (transient EMF E' behind the
  transient reactance X', rotor slip) as Kundur eqs. 7.xx / PSS/E CIMTR1, stator
  transients neglected.
- Grid code: Energinet (Danish TSO), Technical regulation 3.2.2 for PV plants above
  11 kW / 3.2.5 for wind power plants, LVRT reactive current curve (paper Fig. 1):
  extra reactive current 0 at 0.9 p.u., rising linearly to 100 % of rated current at
  0.5 p.u. (slope 2.5 p.u. current per p.u. voltage), area C below 0.2 p.u.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Literal, TypeVar

from opfbench.errors import InputError

FORECASTS = ("off", "oracle")  # pre-fault setpoints without / with Algorithm 3's oracle forecast

EmfMode = Literal["reset", "held", "given"]
TorqueLaw = Literal["quadratic", "constant"]
ActivePowerMode = Literal["constant-power", "ramp"]
InverterControl = Literal["grid-code", "constant-current"]
C = TypeVar("C", bound=str)
NOMINAL_HZ = 50.0
RECOVERY_PU = 0.9  # the recovery threshold |V| ≥ 0.9 p.u.
#: A bus's (and a simulation's, its worst bus's) outcome.
RECOVERED, NOT_RECOVERED, DIVERGED = "recovered", "not-recovered", "diverged"


@dataclass(frozen=True)
class SourceParams:
    """Upstream Thevenin source at the slack bus: impedance `resistance_pu` + j·`impedance_pu`
    (p.u. on the case base; a case with its upstream grid's short-circuit data sets both,
    `opfbench.dynamics.study.case_source`). `emf`: "reset" — |E| set for each operating point so the slack bus
    sits at its scheduled voltage before the fault; "held" — |E| of the no-action
    operating point, kept for every strategy; "given" — |E| = `emf_pu`. E is constant
    during the simulation in every mode."""

    impedance_pu: float = 0.2
    emf: EmfMode = "reset"
    emf_pu: float | None = None
    resistance_pu: float = 0.0

    @property
    def z_pu(self) -> complex:
        """The source impedance R + jX (p.u.)."""
        return self.resistance_pu + 1j * self.impedance_pu


@dataclass(frozen=True)
class MotorParams:
    """Third-order induction motors carrying `share` of each load's P (Kundur's small
    industrial motor, loading factor `loading` → motor MVA base = P_motor / loading)."""

    share: float = 0.5
    rs: float = 0.031
    xs: float = 0.10
    xm: float = 3.2
    rr: float = 0.018
    xr: float = 0.18
    h_s: float = 0.2
    loading: float = 0.8
    torque: TorqueLaw = "quadratic"

    @property
    def x0(self) -> float:
        """Open-circuit reactance Xs + Xm (motor base)."""
        return self.xs + self.xm

    @property
    def xp(self) -> float:
        """Transient reactance X' = Xs + Xm·Xr/(Xm + Xr) (motor base)."""
        return self.xs + self.xm * self.xr / (self.xm + self.xr)

    @property
    def t0p_s(self) -> float:
        """Open-circuit transient time constant T0' = (Xr + Xm)/(ω_s·Rr) in s."""
        return (self.xr + self.xm) / (2 * math.pi * NOMINAL_HZ * self.rr)


@dataclass(frozen=True)
class InverterParams:
    """Current-controlled inverter with the Danish LVRT reactive-current curve.

    Extra reactive current min(slope·max(v_dip − Vf, 0), gc_max) × rated current on top
    of the pre-fault reactive current (held while Vf < v_dip); total current limited to
    `i_max` × rated, reactive priority. Vf: |V| through a `t_filter_s` lag; currents
    follow their references through a `t_lag_s` lag. `active`: "constant-power" (P held,
    active current P/|V| within the limit, so P returns as soon as the limit allows) or
    "ramp" (an active-power cap r·P: r decays to 0 through `t_lag_s` while Vf < v_dip and
    rises at `ramp_pu_s` (fraction of P per s) once Vf ≥ v_dip).
    `area_c_trip`: disconnect for good below `v_trip` (area C), default stay connected.
    `control` "constant-current" replaces all of this by the pre-fault currents (a REGC-type
    converter with fixed commands: what the ANDES cross-check compares)."""

    i_max: float = 1.1
    slope: float = 2.5
    v_dip: float = 0.9
    gc_max: float = 1.0
    t_filter_s: float = 0.010
    t_lag_s: float = 0.020
    active: ActivePowerMode = "constant-power"
    ramp_pu_s: float = 2.0
    area_c_trip: bool = False
    v_trip: float = 0.2
    control: InverterControl = "grid-code"


@dataclass(frozen=True)
class FaultParams:
    """Three-phase fault at `bus` (external number) through reactance `impedance_pu`,
    from `t_on_s` for `duration_s`; simulated to `t_end_s` with fixed step `step_s`."""

    bus: int
    impedance_pu: float = 0.02
    t_on_s: float = 0.1
    duration_s: float = 0.150
    t_end_s: float = 3.0
    step_s: float = 0.001


@dataclass(frozen=True)
class ModelParams:
    """Everything but the fault: source, motors, inverters."""

    source: SourceParams = field(default_factory=SourceParams)
    motors: MotorParams = field(default_factory=MotorParams)
    inverters: InverterParams = field(default_factory=InverterParams)

    def as_dict(self) -> dict:
        return asdict(self)

    def with_variant(self, spec: str) -> "ModelParams":
        """Apply a variant label "key=value[,key=value]" (keys: emf, source, emf-pu,
        motors, inertia, torque, active; each once, emf and emf-pu not together: both set
        the EMF); "reference" changes nothing."""
        if spec == "reference":
            return self
        out = self
        seen: list[str] = []
        for item in spec.split(","):
            key, sep, value = item.partition("=")
            key = key.strip()
            if not sep:
                raise InputError(f"variant {spec!r}: expected key=value items, got {item!r}")
            if key in seen:
                raise InputError(f"variant {spec!r}: {key} is given twice; give each key once")
            if {key, *seen} >= {"emf", "emf-pu"}:
                raise InputError(
                    f"variant {spec!r}: emf and emf-pu both set the source EMF; give one (emf=held|reset, or emf-pu=E)"
                )
            seen.append(key)
            out = _apply(out, key, value.strip(), spec)
        try:
            out.check()
        except InputError as exc:
            raise InputError(f"variant {spec!r}: {exc}") from None
        return out

    def check(self) -> None:
        m, s, i = self.motors, self.source, self.inverters
        if not 0.0 <= m.share <= 1.0:
            raise InputError(f"motor share must lie in [0, 1], got {m.share}")
        if not m.h_s > 0:
            raise InputError(f"motor inertia H must be > 0 s, got {m.h_s}")
        if not s.impedance_pu > 0:
            raise InputError(f"source impedance must be > 0 p.u., got {s.impedance_pu}")
        if not s.resistance_pu >= 0:
            raise InputError(f"source resistance must be ≥ 0 p.u., got {s.resistance_pu}")
        from opfbench.network import V_SETPOINT_PU  # here: the CLI reads this module to build its parser

        lo, hi = V_SETPOINT_PU  # the EMF node is the simulated network's slack
        if s.emf == "given" and (s.emf_pu is None or not lo <= s.emf_pu <= hi):
            raise InputError(f"EMF mode 'given' (emf-pu=X) needs an EMF within [{lo:g}, {hi:g}] p.u., got {s.emf_pu}")
        if s.emf not in ("reset", "held", "given"):
            raise InputError(f"unknown EMF mode {s.emf!r}; choose reset, held or given")
        if m.torque not in ("quadratic", "constant"):
            raise InputError(f"unknown torque law {m.torque!r}; choose quadratic or constant")
        if i.control not in ("grid-code", "constant-current"):
            raise InputError(f"unknown inverter control {i.control!r}; choose grid-code or constant-current")
        if i.active not in ("constant-power", "ramp"):
            raise InputError(f"unknown active-power mode {i.active!r}; choose constant-power or ramp")


def _number(value: str, spec: str) -> float:
    try:
        out = float(value)
    except ValueError:
        raise InputError(f"variant {spec!r}: {value!r} is not a number") from None
    if not math.isfinite(out):
        raise InputError(f"variant {spec!r}: {value!r} is not finite")
    return out


def _choice(value: str, allowed: tuple[C, ...], message: str) -> C:
    """`value` as the one of `allowed` it equals; InputError(`message`) if none."""
    for option in allowed:
        if option == value:
            return option
    raise InputError(message)


def _apply(p: ModelParams, key: str, value: str, spec: str) -> ModelParams:
    if key == "emf":
        emf: EmfMode = _choice(value, ("reset", "held"), f"variant {spec!r}: emf must be reset or held (a value: emf-pu=X)")
        return replace(p, source=replace(p.source, emf=emf))
    if key == "emf-pu":
        return replace(p, source=replace(p.source, emf="given", emf_pu=_number(value, spec)))
    if key == "source":
        return replace(p, source=replace(p.source, impedance_pu=_number(value, spec)))
    if key == "motors":
        return replace(p, motors=replace(p.motors, share=_number(value, spec)))
    if key == "inertia":
        return replace(p, motors=replace(p.motors, h_s=_number(value, spec)))
    if key == "torque":
        law: TorqueLaw = _choice(value, ("quadratic", "constant"), f"unknown torque law {value!r}; choose quadratic or constant")
        return replace(p, motors=replace(p.motors, torque=law))
    if key == "active":
        mode: ActivePowerMode = _choice(
            value, ("constant-power", "ramp"), f"unknown active-power mode {value!r}; choose constant-power or ramp"
        )
        return replace(p, inverters=replace(p.inverters, active=mode))
    raise InputError(f"variant {spec!r}: unknown key {key!r}; use emf, emf-pu, source, motors, inertia, torque, active")


SENSITIVITY_VARIANTS = ("reference", "emf=held", "source=0.1", "source=0.3", "motors=0.3", "motors=0.7")
