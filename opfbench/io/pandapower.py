"""pandapower net → `Network`: the conversion, element by element, with pandapower's own
models so that our power flow and pandapower's `runpp` (default options) agree.

- **Buses**: in-service buses; closed bus-bus switches (z_ohm ≤ 0) fuse their buses (the
  lowest pandapower index names the fused bus); open ones leave them apart; a closed
  bus-bus switch with z_ohm > 0 is an impedance branch (r : x = 2 : 1, pandapower's
  default `switch_rx_ratio`). Voltage limits from `min_vm_pu`/`max_vm_pu` (0.9/1.1 where
  not given).
- **Lines**: r, x from ohm/km × length / parallel; charging b = 2π·f·C·length·parallel
  and conductance g from `g_us_per_km`, both as the π model's shunts (p.u. on the
  from bus's voltage and the net's `sn_mva`).
- **Two-winding transformers**: short-circuit impedance from vk/vkr on the transformer's
  rating, referred to the low-voltage side's tap-adjusted voltage; iron losses (pfe_kw)
  and magnetizing current (i0_percent) as the shunt of pandapower's T model (default
  `trafo_model="t"`), turned into the equivalent π (pandapower's `_wye_delta`); the
  off-nominal ratio (vn_hv/vn_lv)/(bus ratio) with the tap position (`tap_side`,
  `tap_pos` − `tap_neutral`, `tap_step_percent` and `tap_step_degree`, the "Ratio"/
  "Symmetrical" tap changer; "Ideal" phase shifters) and the phase shift `shift_degree`.
  A transformer without `tap_changer_type` has no active tap, as in pandapower 3.x.
- **Switches on branches**: an open line or transformer switch opens that end; a branch
  open at one end hangs at the other with its charging (an auxiliary bus at the open
  end, as pandapower builds it); open at both ends, it is left out.
- **Parallel branches** between the same two buses with the same tap and shift are merged
  into one (admittances add; the same power flow and losses), so two transformers in
  parallel do not make a radial feeder look meshed.
- **External grid**: exactly one in service; the slack at its `vm_pu` (its `va_degree`
  only rotates every angle). Its `s_sc_max_mva`/`rx_max`, when given, are the upstream
  source of the fault study.
- **Loads**: one load element per in-service load, P = p_mw·scaling, Q = q_mvar·scaling,
  constant power (voltage-dependent ZIP shares are refused). Several may share a bus.
- **Static generators → DER** of the generic "inverter" kind: rated P̄ = the larger of
  p_mw·scaling and `max_p_mw` (the stored output counts as full output, as in SimBench),
  nameplate S̄ = the larger of `sn_mva` and P̄/der_pf (default der_pf 0.90: the
  VDE-AR-N 4105 power factor at full output, see `opfbench.capability`); energy from the
  `type` (PV → solar, wind → wind, …, SimBench's aggregated LV renewables "lv_RES" →
  solar). The stored output P, Q is kept as the net's stored operating point.
- **Shunts**: p_mw/q_mvar × step × (bus voltage / shunt voltage)² as bus shunts.
- Buses the in-service branches leave unconnected to the slack are dropped with their
  elements (as pandapower sets them out of service), and said so in a note.

Refused, with the table and index named (never dropped silently): voltage-controlled
`gen`, three-winding transformers, storage, impedance elements, ward equivalents, motors,
DC lines and converters, FACTS devices, unbalanced elements, tabular tap changers, a
second tap changer, a net with no or two external grids, voltage-dependent loads, a
static generator without a positive rating.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass

import numpy as np
import pandas as pd

from opfbench.errors import CaseFormatError, NetworkError
from opfbench.network import DER, Network

DEFAULT_DER_PF = 0.90  # S̄ = P̄ / 0.90: VDE-AR-N 4105's cos φ 0.90 at full output
SWITCH_RX_RATIO = 2.0  # pandapower's default `switch_rx_ratio`
DEFAULT_VMIN, DEFAULT_VMAX = 0.9, 1.1

#: Element tables the converter cannot map, with the reason it gives.
REFUSED_TABLES = {
    "gen": "voltage-controlled generators (PV buses) are not modelled by the local rules and formulations",
    "trafo3w": "three-winding transformers are not modelled",
    "storage": "storage units are not modelled (their charging schedule is not part of the benchmark)",
    "impedance": "impedance elements are not modelled",
    "ward": "ward equivalents are not modelled",
    "xward": "extended ward equivalents are not modelled",
    "motor": "motors are not modelled (give them as loads)",
    "dcline": "DC lines are not modelled",
    "line_dc": "DC lines are not modelled",
    "bus_dc": "DC buses are not modelled",
    "vsc": "voltage-source converters are not modelled",
    "vsc_stacked": "voltage-source converters are not modelled",
    "vsc_bipolar": "voltage-source converters are not modelled",
    "source_dc": "DC sources are not modelled",
    "load_dc": "DC loads are not modelled",
    "svc": "FACTS devices are not modelled",
    "ssc": "FACTS devices are not modelled",
    "tcsc": "FACTS devices are not modelled",
    "asymmetric_load": "unbalanced (per-phase) elements are not modelled",
    "asymmetric_sgen": "unbalanced (per-phase) elements are not modelled",
}
#: sgen `type` patterns → primary energy (first match wins; case-insensitive).
ENERGY_OF_TYPE = (
    (r"pv|solar|lv_res", "solar"),
    (r"wind|wp", "wind"),
    (r"biomass|bm|biogas", "biomass"),
    (r"hydro|water", "hydro"),
)


@dataclass(frozen=True)
class Converted:
    """A converted net: the network, which pandapower row each load element and DER came
    from, the stored operating point (MW/MVAr per element) and notes on what was done."""

    network: Network
    load_index: np.ndarray
    sgen_index: np.ndarray
    stored_load_p_mw: np.ndarray
    stored_load_q_mvar: np.ndarray
    stored_der_p_mw: np.ndarray
    stored_der_q_mvar: np.ndarray
    bus_of: dict[int, int]
    short_circuit: tuple[float, float] | None
    notes: tuple[str, ...]


_REQUIRED = None
"""`_Table.num`'s `empty`/`absent` for a value pandapower needs: an empty cell or a missing
column is refused, never replaced by a guess."""


@dataclass(frozen=True)
class _Table:
    """A pandapower element table read strictly: a cell that is not a finite number (text,
    true/false, ±inf) is refused with table, index, column and value named; an empty (NaN)
    cell or a missing column takes a default only where pandapower itself has one (an
    optional column such as max_p_mw or tap_pos), and is refused where pandapower needs the
    value (a load's p_mw, a line's length); bus references must name a row of 'bus';
    true/false columns hold true/false (or 0/1), not text."""

    frame: pd.DataFrame
    name: str
    label: str

    @classmethod
    def of(cls, pnet, name: str, label: str, in_service: bool = True) -> "_Table":
        """The table `name` of `pnet` (only its in-service rows with `in_service`)."""
        frame = pnet[name] if name in pnet else pd.DataFrame()
        table = cls(frame, name, label)
        return table.rows(table.flag("in_service", True)) if in_service and len(frame) else table

    def __len__(self) -> int:
        return len(self.frame)

    @property
    def index(self) -> pd.Index:
        return self.frame.index

    def rows(self, mask: np.ndarray) -> "_Table":
        return _Table(self.frame[mask], self.name, self.label)

    def error(self, row: object, problem: str) -> CaseFormatError:
        return CaseFormatError(f"{self.label}: table '{self.name}' index {row}: {problem}")

    def num(self, column: str, empty: float | None = _REQUIRED, absent: float | None = _REQUIRED) -> np.ndarray:
        """The column as floats; `empty`: the value of an empty cell (None: refused);
        `absent`: the value of every row when the column is missing (None: refused)."""
        if column not in self.frame:
            if absent is None and len(self.frame):
                raise CaseFormatError(f"{self.label}: table '{self.name}' has no column {column!r}")
            return np.full(len(self.frame), np.nan if absent is None else absent, dtype=float)
        raw = self.frame[column]
        if pd.api.types.is_bool_dtype(raw):
            is_bool = np.ones(len(raw), dtype=bool)
        elif raw.dtype == object:
            is_bool = raw.map(lambda v: isinstance(v, (bool, np.bool_))).to_numpy(dtype=bool)
        else:
            is_bool = np.zeros(len(raw), dtype=bool)
        values = pd.to_numeric(raw.where(~is_bool), errors="coerce").to_numpy(dtype=float)
        blank = raw.isna().to_numpy()
        bad = (~blank & ~np.isfinite(values)) | is_bool
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise self.error(self.frame.index[i], f"{column} is {raw.iloc[i]!r}, not a finite number")
        if blank.any():
            if empty is None:
                i = int(np.flatnonzero(blank)[0])
                raise self.error(self.frame.index[i], f"{column} is empty; pandapower's power flow needs a number there")
            values[blank] = empty
        return values

    def positive(self, column: str, empty: float | None = _REQUIRED, absent: float | None = _REQUIRED) -> np.ndarray:
        """`num` of a quantity that must be > 0 (a length, a rating, a voltage); a NaN
        `empty`/`absent` default passes (an optional value not given)."""
        values = self.num(column, empty, absent)
        bad = values <= 0
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise self.error(self.frame.index[i], f"{column} is {values[i]:g}; it must be > 0")
        return values

    def flag(self, column: str, default: bool) -> np.ndarray:
        """A true/false column (`default` where empty or missing)."""
        if column not in self.frame:
            return np.full(len(self.frame), default, dtype=bool)
        raw = self.frame[column]
        ok = raw.map(_is_flag).to_numpy(dtype=bool)
        if not ok.all():
            i = int(np.flatnonzero(~ok)[0])
            raise self.error(self.frame.index[i], f"{column} is {raw.iloc[i]!r}, not true or false")
        return raw.astype(object).where(raw.notna(), default).astype(bool).to_numpy()

    def buses(self, column: str, bus_index: pd.Index) -> np.ndarray:
        """A column of bus references (pandapower bus indices), each a row of 'bus'."""
        values = self.num(column)
        known = np.isin(values, bus_index.to_numpy(dtype=float))
        if not known.all():
            i = int(np.flatnonzero(~known)[0])
            raise self.error(self.frame.index[i], f"{column} {values[i]:g} is not a bus of table 'bus'")
        return values.astype(np.int64)


def _is_flag(value: object) -> bool:
    """A true/false cell: a bool, 0 or 1, or empty."""
    if isinstance(value, (bool, np.bool_)):
        return True
    if isinstance(value, (int, float, np.number)):
        return value in (0, 1) or math.isnan(value)
    return value is None or value is pd.NA


def _refuse_unmapped(pnet, label: str) -> None:
    for table, reason in REFUSED_TABLES.items():
        df = pnet.get(table) if hasattr(pnet, "get") else None
        if isinstance(df, pd.DataFrame) and len(df):
            active = _Table.of(pnet, table, label).index
            if len(active):
                more = f" (and {len(active) - 1} more)" if len(active) > 1 else ""
                raise CaseFormatError(f"{label}: table '{table}' index {active[0]}{more}: {reason}")


class _Fuse:
    """Union-find over pandapower bus indices (closed bus-bus switches); the smallest index
    of a group represents it."""

    def __init__(self, buses: np.ndarray):
        self.parent = {int(b): int(b) for b in buses}

    def find(self, b: int) -> int:
        root = b
        while self.parent[root] != root:
            root = self.parent[root]
        while self.parent[b] != root:
            self.parent[b], b = root, self.parent[b]
        return root

    def join(self, a: int, b: int) -> None:
        ra, rb = self.find(a), self.find(b)
        if ra != rb:
            self.parent[max(ra, rb)] = min(ra, rb)


@dataclass
class _Branches:
    """Branch rows being collected (pandapower bus indices at this stage; -1 = open end)."""

    f: list[int]
    t: list[int]
    r: list[float]
    x: list[float]
    b: list[float]
    g: list[float]
    tap: list[float]
    shift: list[float]
    kv_f: list[float]
    kv_t: list[float]

    @classmethod
    def empty(cls) -> "_Branches":
        return cls([], [], [], [], [], [], [], [], [], [])

    def add(self, f, t, r, x, b, g, tap, shift, kv_f, kv_t) -> None:
        for name, value in zip(
            ("f", "t", "r", "x", "b", "g", "tap", "shift", "kv_f", "kv_t"),
            (f, t, r, x, b, g, tap, shift, kv_f, kv_t),
            strict=True,
        ):
            getattr(self, name).extend(np.atleast_1d(value).tolist())


@dataclass(frozen=True)
class _Grid:
    """What every element table is read against: the buses (each with a positive nominal
    voltage vn_kv, and whether it is in service) and the switches."""

    label: str
    sn_mva: float
    f_hz: float
    vn_kv: pd.Series
    on: pd.Series
    switches: _Table

    @classmethod
    def of(cls, pnet, label: str) -> "_Grid":
        bus = _Table.of(pnet, "bus", label, in_service=False)
        vn = pd.Series(bus.positive("vn_kv"), index=bus.index)
        on = pd.Series(bus.flag("in_service", True), index=bus.index)
        switches = _Table.of(pnet, "switch", label, in_service=False)
        if len(switches):
            kinds = switches.frame["et"].astype(object)
            bad = ~kinds.isin(["b", "l", "t", "t3"]).to_numpy()
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise switches.error(switches.index[i], f"et is {kinds.iloc[i]!r}; a switch's et is b, l, t or t3")
            switches.buses("bus", bus.index)
            switches.rows((kinds == "b").to_numpy()).buses("element", bus.index)
        sn, f_hz = (
            float(pnet[key]) if isinstance(pnet[key], (int, float, np.number)) else math.nan for key in ("sn_mva", "f_hz")
        )
        for key, value in (("sn_mva", sn), ("f_hz", f_hz)):
            if not (math.isfinite(value) and value > 0):
                raise CaseFormatError(f"{label}: the net's {key} is {pnet[key]!r}; it must be a positive number")
        return cls(label, sn, f_hz, vn, on, switches)

    def open_ends(self, et: str, table: _Table, ends: tuple[str, str]) -> tuple[np.ndarray, ...]:
        """(bus at the first end, at the second, open at the first, open at the second) per
        row of `table`: its bus references, and whether an open switch of type `et` lies
        between the element and that end's bus, or that bus is out of service."""
        sw = self.switches
        pairs: set[tuple[int, int]] = set()
        if len(sw):
            sw = sw.rows((sw.frame["et"] == et).to_numpy() & ~sw.flag("closed", True))
            pairs = set(zip(sw.num("element").astype(int), sw.num("bus").astype(int), strict=True))
        buses, opened = [], []
        for end in ends:
            bus = table.buses(end, self.vn_kv.index)
            buses.append(bus)
            at = np.array([(int(i), int(bb)) in pairs for i, bb in zip(table.index, bus, strict=True)], dtype=bool)
            opened.append(at | ~self.on.reindex(bus).to_numpy(dtype=bool))
        return buses[0], buses[1], opened[0], opened[1]


def _lines(grid: _Grid, pnet, br: _Branches) -> None:
    line = _Table.of(pnet, "line", grid.label)
    if not len(line):
        return
    fb, tb, open_f, open_t = grid.open_ends("l", line, ("from_bus", "to_bus"))
    kv_f = grid.vn_kv.reindex(fb).to_numpy()
    z_base = kv_f**2 / grid.sn_mva
    length, par = line.positive("length_km"), line.positive("parallel", absent=1.0)
    r_km, x_km = line.num("r_ohm_per_km"), line.num("x_ohm_per_km")
    zero = (r_km == 0) & (x_km == 0)
    if zero.any():
        raise line.error(
            line.index[zero][0],
            "r_ohm_per_km = x_ohm_per_km = 0: a line without impedance is not modelled (join its buses with a closed "
            "bus-bus switch, or give the line its impedance)",
        )
    r = r_km * length / z_base / par
    x = x_km * length / z_base / par
    b = 2 * grid.f_hz * math.pi * line.num("c_nf_per_km") * 1e-9 * z_base * length * par
    g = line.num("g_us_per_km", empty=0.0, absent=0.0) * 1e-6 * z_base * length * par
    f = np.where(open_f, -1, fb)
    t = np.where(open_t, -1, tb)
    br.add(f, t, r, x, b, g, np.ones(len(line)), np.zeros(len(line)), kv_f, grid.vn_kv.reindex(tb).to_numpy())


def _tap_changer(table: _Table) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vn_hv, vn_lv, extra shift in degrees) after the tap changers, as pandapower 3.x's
    `_calc_tap_from_dataframe` without characteristic tables."""
    trafo, label = table.frame, table.label
    vnh, vnl = table.positive("vn_hv_kv"), table.positive("vn_lv_kv")
    shift = np.zeros(len(trafo))
    raw = trafo["tap_changer_type"] if "tap_changer_type" in trafo else pd.Series(None, index=trafo.index, dtype=object)
    kind = raw.astype(object).where(raw.notna(), "").astype(str).str.strip()
    if "tap2_pos" in trafo and "tap2_changer_type" in trafo:
        second = trafo["tap2_pos"].notna().to_numpy() & trafo["tap2_changer_type"].notna().to_numpy()
        if second.any():
            raise CaseFormatError(
                f"{label}: table 'trafo' index {trafo.index[second][0]}: a second tap changer (tap2_*) is not modelled"
            )
    tabular = table.flag("tap_dependency_table", False) | (kind.to_numpy() == "Tabular")
    if tabular.any():
        i = trafo.index[tabular][0]
        raise CaseFormatError(f"{label}: table 'trafo' index {i}: tabular tap changers (characteristic tables) are not modelled")
    unknown = ~kind.isin(["", "None", "nan", "Ratio", "Symmetrical", "Ideal"]).to_numpy()
    if unknown.any():
        i = trafo.index[unknown][0]
        raise CaseFormatError(f"{label}: table 'trafo' index {i}: unknown tap_changer_type {kind[i]!r}")
    optional = {"empty": math.nan, "absent": math.nan}  # no tap changer
    diff = np.nan_to_num(table.num("tap_pos", **optional) - table.num("tap_neutral", **optional), nan=0.0)
    step_pct, step_deg = (table.num(c, empty=0.0, absent=0.0) for c in ("tap_step_percent", "tap_step_degree"))
    side = trafo["tap_side"].astype(str).to_numpy() if "tap_side" in trafo else np.full(len(trafo), "hv")
    ratio_type = kind.isin(["Ratio", "Symmetrical"]).to_numpy()
    ideal = (kind == "Ideal").to_numpy()
    for which, vn, direction in (("hv", vnh, 1.0), ("lv", vnl, -1.0)):
        here = side == which
        m = ratio_type & here
        if m.any():  # pandapower's complex tap changer: magnitude and angle of the step
            du = vn[m] * step_pct[m] * diff[m] / 100
            ang = np.deg2rad(step_deg[m])
            shift[m] += np.rad2deg(np.arctan(direction * du * np.sin(ang) / (vn[m] + du * np.cos(ang))))
            vn[m] = np.sqrt((vn[m] + du * np.cos(ang)) ** 2 + (du * np.sin(ang)) ** 2)
        m = ideal & here
        if m.any():
            by_degree = step_deg[m] != 0
            shift[m] += np.where(
                by_degree, direction * diff[m] * step_deg[m], direction * 2 * np.rad2deg(np.arcsin(diff[m] * step_pct[m] / 200))
            )
    return vnh, vnl, shift


def _trafos(grid: _Grid, pnet, br: _Branches) -> None:
    table = _Table.of(pnet, "trafo", grid.label)
    if not len(table):
        return
    for col in ("leakage_resistance_ratio_hv", "leakage_reactance_ratio_hv"):
        ratio = table.num(col, empty=0.5, absent=0.5)
        if np.any(ratio != 0.5):
            i = table.index[ratio != 0.5][0]
            raise table.error(i, f"{col} ≠ 0.5 (an asymmetric T model) is not modelled")
    hv, lv, open_f, open_t = grid.open_ends("t", table, ("hv_bus", "lv_bus"))
    vn_hv_bus, vn_lv_bus = grid.vn_kv.reindex(hv).to_numpy(), grid.vn_kv.reindex(lv).to_numpy()
    vnh, vnl, tap_shift = _tap_changer(table)
    sn, par = table.positive("sn_mva"), table.positive("parallel", absent=1.0)
    vk, vkr = table.positive("vk_percent"), table.num("vkr_percent")
    z_ref = (vnl / vn_lv_bus) ** 2 * grid.sn_mva  # referred to the LV side's tap-adjusted voltage
    z = vk / 100 / sn * z_ref
    r = vkr / 100 / sn * z_ref
    x = np.sign(z) * np.sqrt(z**2 - r**2)
    r, x = r / par, x / par
    # magnetizing branch (pandapower's `_calc_y_from_dataframe`), p.u. on the LV bus base:
    # rated at the table's vn_lv_kv, referred through the tap-adjusted LV voltage
    vn_lv_rated = table.positive("vn_lv_kv")
    pfe_mw = table.num("pfe_kw") * 1e-3
    ym_mva = table.num("i0_percent") / 100 * sn
    b_mva = -np.sqrt(np.maximum(ym_mva**2 - pfe_mw**2, 0.0))
    scale = (vn_lv_bus**2 / grid.sn_mva) * par / vn_lv_rated**2 / (vnl / vn_lv_rated) ** 2
    g_pu, b_pu = pfe_mw * scale, b_mva * scale
    r, x, g_pu, b_pu = _wye_delta(r, x, g_pu, b_pu)
    ratio = (vnh / vnl) / (vn_hv_bus / vn_lv_bus)
    shift = table.num("shift_degree", absent=0.0) + tap_shift
    f = np.where(open_f, -1, hv)
    t = np.where(open_t, -1, lv)
    br.add(f, t, r, x, b_pu, g_pu, ratio, shift, vn_hv_bus, vn_lv_bus)


def _wye_delta(r: np.ndarray, x: np.ndarray, g: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, ...]:
    """The T model (series impedance split 1:1 around the magnetizing admittance g + jb)
    as its equivalent π: series r + jx and the shunt g + jb split between the two ends
    (pandapower's `_wye_delta` with leakage ratios 0.5; the two shunts are then equal)."""
    r, x, g, b = (np.array(a, dtype=float) for a in (r, x, g, b))
    t = (g != 0) | (b != 0)
    za = zb = (r[t] + 1j * x[t]) / 2
    zc = 1 / (g[t] + 1j * b[t])
    total = za * zb + za * zc + zb * zc
    z_series = total / zc
    y_end = 1 / (total / zb)
    r[t], x[t] = z_series.real, z_series.imag
    g[t], b[t] = 2 * y_end.real, 2 * y_end.imag
    return r, x, g, b


def _element_names(table: _Table, kept: np.ndarray) -> list[str | None]:
    """Each row's `name` where it names that row alone among the `kept` rows (printable,
    non-empty text, given once); None otherwise (the network then derives one from the
    kind and bus, `Network.der_names`)."""
    raw = table.frame["name"].tolist() if "name" in table.frame else [None] * len(table)
    text = [v.strip() if isinstance(v, str) and v.strip() and v.isprintable() else None for v in raw]
    count = Counter(t for t, keep in zip(text, kept, strict=True) if keep and t is not None)
    return [t if t is not None and count[t] == 1 else None for t in text]


def _energy(kind: object) -> str:
    text = "" if kind is None or (isinstance(kind, float) and math.isnan(kind)) else str(kind)
    for pattern, energy in ENERGY_OF_TYPE:
        if re.search(pattern, text, flags=re.IGNORECASE):
            return energy
    return "other"


def from_pandapower(pnet, name: str, der_pf: float = DEFAULT_DER_PF, label: str | None = None) -> Converted:
    """Convert a pandapower net (see the module docstring); `label` names it in errors."""
    label = label or name
    if not 0 < der_pf <= 1:
        raise CaseFormatError(f"{label}: der_pf must lie in (0, 1], got {der_pf}")
    _refuse_unmapped(pnet, label)
    notes: list[str] = []
    grid = _Grid.of(pnet, label)
    bus = _Table.of(pnet, "bus", label, in_service=False)
    on_bus = bus.index[grid.on.to_numpy()].to_numpy(dtype=int)
    ext = _Table.of(pnet, "ext_grid", label)
    if len(ext) != 1:
        raise CaseFormatError(
            f"{label}: needs exactly one in-service external grid (table 'ext_grid'), found {len(ext)}"
            + (f" (index {', '.join(str(i) for i in ext.index)})" if len(ext) else "")
        )

    fuse = _Fuse(bus.index.to_numpy(dtype=int))
    br = _Branches.empty()
    sw = grid.switches
    bb = sw.rows((sw.frame["et"] == "b").to_numpy() & sw.flag("closed", True)) if len(sw) else sw
    ends = zip(bb.num("bus").astype(int), bb.num("element").astype(int), bb.num("z_ohm", absent=0.0), strict=True)
    for a, e, z in ends if len(bb) else ():
        if z > 0:  # an impedance branch (pandapower's switch_rx_ratio)
            kv_a = float(grid.vn_kv[a])
            zpu = z / (kv_a**2 / grid.sn_mva)
            br.add(
                a,
                e,
                zpu * SWITCH_RX_RATIO / math.hypot(1, SWITCH_RX_RATIO),
                zpu / math.hypot(1, SWITCH_RX_RATIO),
                0.0,
                0.0,
                1.0,
                0.0,
                kv_a,
                float(grid.vn_kv[e]),
            )
        else:
            fuse.join(a, e)
    _lines(grid, pnet, br)
    _trafos(grid, pnet, br)

    f = np.array([fuse.find(v) if v >= 0 else -1 for v in br.f], dtype=int)
    t = np.array([fuse.find(v) if v >= 0 else -1 for v in br.t], dtype=int)
    r, x, b, g = (np.array(getattr(br, k), dtype=float) for k in ("r", "x", "b", "g"))
    tap, shift = np.array(br.tap, dtype=float), np.array(br.shift, dtype=float)
    both_open = (f < 0) & (t < 0)
    keep = ~both_open & ~((f == t) & (f >= 0))  # a branch inside a fused bus carries nothing
    # auxiliary buses at open ends
    reps = sorted({fuse.find(int(v)) for v in on_bus})
    next_id = int(bus.index.max()) + 1
    aux_kv: list[float] = []
    for k in np.flatnonzero(keep & ((f < 0) | (t < 0))):
        kv_end = br.kv_f[k] if f[k] < 0 else br.kv_t[k]
        if f[k] < 0:
            f[k] = next_id
        else:
            t[k] = next_id
        aux_kv.append(kv_end)
        next_id += 1
    n_aux = len(aux_kv)
    if n_aux:
        notes.append(
            f"{n_aux} branch end(s) opened by a switch or an out-of-service bus: the branch hangs at its other end (auxiliary bus, as pandapower)"
        )
    f, t, r, x, b, g, tap, shift = (a[keep] for a in (f, t, r, x, b, g, tap, shift))
    f, t, r, x, b, g, tap, shift, merged = _merge_parallel(f, t, r, x, b, g, tap, shift)
    if merged:
        notes.append(f"{merged} parallel branch(es) merged with their twin (same buses, tap and shift): the same power flow")
    bridged = _bridges(f, t) & (shift != 0)
    if bridged.any():
        shift = np.where(bridged, 0.0, shift)
        notes.append(
            f"the phase shift of {int(bridged.sum())} transformer(s) on no loop dropped: it only rotates the angles beyond "
            "it (no |V|, flow or loss changes); angles are reported without it"
        )

    ids = np.array(reps + list(range(int(bus.index.max()) + 1, next_id)), dtype=int)
    pos = {int(v): k for k, v in enumerate(ids)}
    ext_bus = int(ext.buses("bus", bus.index)[0])
    slack_pp = fuse.find(ext_bus)
    if slack_pp not in pos:
        raise CaseFormatError(f"{label}: the external grid's bus {ext_bus} is out of service")
    kv = np.concatenate([grid.vn_kv.reindex(reps).to_numpy(dtype=float), np.array(aux_kv, dtype=float)])
    reachable = _reachable(len(ids), np.array([pos[v] for v in f]), np.array([pos[v] for v in t]), pos[slack_pp])
    if not reachable.all():
        lost = ids[~reachable]
        notes.append(
            f"{lost.size} bus(es) not connected to the external grid dropped with their elements, as pandapower "
            f"leaves them out of service: {', '.join(str(i) for i in lost[:12])}{' …' if lost.size > 12 else ''}"
        )
    keep_bus = np.flatnonzero(reachable)
    renum = -np.ones(len(ids), dtype=int)
    renum[keep_bus] = np.arange(keep_bus.size)
    fi, ti = renum[[pos[v] for v in f]], renum[[pos[v] for v in t]]
    branch_ok = (fi >= 0) & (ti >= 0)
    bus_of = {int(b_): int(renum[pos[fuse.find(int(b_))]]) for b_ in on_bus if renum[pos[fuse.find(int(b_))]] >= 0}
    ids, kv = ids[keep_bus], kv[keep_bus]
    n = ids.size
    lo = pd.Series(bus.num("min_vm_pu", empty=DEFAULT_VMIN, absent=DEFAULT_VMIN), index=bus.index)
    hi = pd.Series(bus.num("max_vm_pu", empty=DEFAULT_VMAX, absent=DEFAULT_VMAX), index=bus.index)
    vmin, vmax = np.full(n, -np.inf), np.full(n, np.inf)
    for b_, member in bus_of.items():  # a fused bus takes the tightest limits of its members
        vmin[member], vmax[member] = max(vmin[member], lo[b_]), min(vmax[member], hi[b_])
    for aux in np.flatnonzero(~np.isfinite(vmin)):  # an auxiliary bus: the limits of the bus it hangs at
        j = int(np.concatenate([ti[fi == aux], fi[ti == aux]])[0])
        vmin[aux], vmax[aux] = vmin[j], vmax[j]

    # loads
    load = _Table.of(pnet, "load", label)
    zip_cols = [
        c
        for c in (
            "const_z_percent",
            "const_i_percent",
            "const_z_p_percent",
            "const_i_p_percent",
            "const_z_q_percent",
            "const_i_q_percent",
        )
        if c in load.frame
    ]
    for col in zip_cols:
        bad = load.num(col, empty=0.0) != 0
        if bad.any():
            raise load.error(
                load.index[bad][0], f"{col} ≠ 0 (a voltage-dependent load) is not modelled; loads are constant power"
            )
    load_at = np.array([bus_of.get(int(v), -1) for v in load.buses("bus", bus.index)], dtype=int)
    lscale = load.num("scaling", absent=1.0)
    lp, lq = load.num("p_mw") * lscale, load.num("q_mvar") * lscale
    dropped_loads = int((load_at < 0).sum())
    keep_load = load_at >= 0
    load_index = load.index.to_numpy()[keep_load]
    load_bus, lp, lq = load_at[keep_load], lp[keep_load], lq[keep_load]

    # static generators → DER
    sgen = _Table.of(pnet, "sgen", label)
    sg_at = np.array([bus_of.get(int(v), -1) for v in sgen.buses("bus", bus.index)], dtype=int)
    sscale = sgen.num("scaling", absent=1.0)
    sp, sq = sgen.num("p_mw") * sscale, sgen.num("q_mvar", absent=0.0) * sscale
    rating = np.maximum(sp, sgen.num("max_p_mw", empty=0.0, absent=0.0))  # max_p_mw: an OPF limit, often not given
    bad = (rating <= 0) & (sg_at >= 0)
    if bad.any():
        i = sgen.index[bad][0]
        raise sgen.error(i, "no positive rating (p_mw·scaling and max_p_mw ≤ 0): it cannot be a DER")
    s_rated = np.maximum(sgen.num("sn_mva", empty=0.0, absent=0.0), rating / der_pf)
    types = sgen.frame["type"].tolist() if "type" in sgen.frame else [None] * len(sgen)
    keep_sg = sg_at >= 0
    dropped_sgens = int((~keep_sg).sum())
    names = _element_names(sgen, keep_sg)
    ders = tuple(
        DER(int(sg_at[i]), "inverter", float(rating[i]), float(s_rated[i]), _energy(types[i]), names[i])  # type: ignore[arg-type]
        for i in np.flatnonzero(keep_sg)
    )
    if dropped_loads or dropped_sgens:
        notes.append(
            f"{dropped_loads} load(s) and {dropped_sgens} static generator(s) at dropped or out-of-service buses left out"
        )

    # shunts
    gs, bs = np.zeros(n), np.zeros(n)
    shunt = _Table.of(pnet, "shunt", label)
    if len(shunt):
        tables = shunt.flag("step_dependency_table", False)
        if tables.any():
            raise shunt.error(shunt.index[tables][0], "shunt characteristic tables are not modelled")
        shunt_bus = shunt.buses("bus", bus.index)
        at = np.array([bus_of.get(int(v), -1) for v in shunt_bus], dtype=int)
        vbus = grid.vn_kv.reindex(shunt_bus).to_numpy(dtype=float)
        vsh = shunt.positive("vn_kv", empty=math.nan, absent=math.nan)  # not given: the bus's
        factor = shunt.num("step", absent=1.0) * (vbus / np.where(np.isfinite(vsh), vsh, vbus)) ** 2
        ok = at >= 0
        np.add.at(gs, at[ok], (shunt.num("p_mw", absent=0.0) * factor)[ok])
        np.add.at(bs, at[ok], -(shunt.num("q_mvar") * factor)[ok])

    bus_p, bus_q = np.zeros(n), np.zeros(n)
    np.add.at(bus_p, load_bus, lp)
    np.add.at(bus_q, load_bus, lq)
    slack = int(renum[pos[slack_pp]])
    btype = np.ones(n, dtype=int)
    btype[slack] = 3
    va = float(ext.num("va_degree", empty=0.0, absent=0.0)[0])
    if va != 0:
        notes.append(f"the external grid's angle {va:g}° only rotates every bus angle; angles are reported relative to it")
    vm = float(ext.positive("vm_pu")[0])
    try:
        network = Network(
            name=name,
            base_mva=grid.sn_mva,
            bus_ids=ids,
            bus_type=btype,
            base_kv=kv,
            load_p_mw=bus_p,
            load_q_mvar=bus_q,
            gs_mw=gs,
            bs_mvar=bs,
            vmin=vmin,
            vmax=vmax,
            f=fi[branch_ok],
            t=ti[branch_ok],
            r=r[branch_ok],
            x=x[branch_ok],
            b=b[branch_ok],
            g=g[branch_ok],
            tap=tap[branch_ok],
            shift=shift[branch_ok],
            status=np.ones(int(branch_ok.sum()), dtype=bool),
            slack=slack,
            v_slack=vm,
            ders=ders,
            load_bus=load_bus if load_bus.size else np.zeros(0, dtype=int),
        )
    except NetworkError as exc:
        raise CaseFormatError(f"{label}: {exc}") from None
    sc = None
    s_sc, rx = (float(ext.num(c, empty=math.nan, absent=math.nan)[0]) for c in ("s_sc_max_mva", "rx_max"))
    if np.isfinite(s_sc) and s_sc > 0:
        sc = (float(s_sc), float(rx) if np.isfinite(rx) else 0.0)
    return Converted(
        network,
        load_index,
        sgen.index.to_numpy()[keep_sg],
        lp,
        lq,
        sp[keep_sg],
        sq[keep_sg],
        bus_of,
        sc,
        tuple(notes),
    )


def _merge_parallel(
    f: np.ndarray, t: np.ndarray, r: np.ndarray, x: np.ndarray, b: np.ndarray, g: np.ndarray, tap: np.ndarray, shift: np.ndarray
) -> tuple:
    """Merge branches with the same (from, to) buses, tap and shift into one: series
    admittances and shunts add (exact for the π model with a common ideal transformer)."""
    groups: dict[tuple, list[int]] = {}
    for k in range(len(f)):
        groups.setdefault((int(f[k]), int(t[k]), float(tap[k]), float(shift[k])), []).append(k)
    rows, merged = [], 0
    out: dict[str, list[float]] = {name: [] for name in ("f", "t", "r", "x", "b", "g", "tap", "shift")}
    for (fk, tk, tp, sh), members in groups.items():
        ys = sum(1 / complex(r[k], x[k]) for k in members)
        z = 1 / ys
        merged += len(members) - 1
        rows.append(members[0])
        for name, value in zip(
            out, (fk, tk, z.real, z.imag, sum(b[k] for k in members), sum(g[k] for k in members), tp, sh), strict=True
        ):
            out[name].append(value)
    arrays = [np.array(out[name], dtype=int if name in ("f", "t") else float) for name in out]
    return (*arrays, merged)


def _bridges(f: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Bool per branch: a bridge (on no cycle), i.e. removing it splits its component."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    ids, inv = np.unique(np.concatenate([f, t]), return_inverse=True)
    fi, ti = inv[: len(f)], inv[len(f) :]
    n = ids.size

    def parts(mask: np.ndarray) -> int:
        graph = sp.csr_matrix((np.ones(int(mask.sum())), (fi[mask], ti[mask])), shape=(n, n))
        return connected_components(graph, directed=False)[0]

    base = parts(np.ones(len(f), dtype=bool))
    out = np.zeros(len(f), dtype=bool)
    if len(f) == n - base:  # a forest: every branch is a bridge
        return np.ones(len(f), dtype=bool)
    for k in range(len(f)):
        mask = np.ones(len(f), dtype=bool)
        mask[k] = False
        out[k] = parts(mask) > base
    return out


def _reachable(n: int, f: np.ndarray, t: np.ndarray, root: int) -> np.ndarray:
    import scipy.sparse as sp
    from scipy.sparse.csgraph import breadth_first_order

    graph = sp.csr_matrix((np.ones(len(f)), (f, t)), shape=(n, n))
    order = breadth_first_order(graph, root, directed=False, return_predecessors=False)
    seen = np.zeros(n, dtype=bool)
    seen[order] = True
    return seen
