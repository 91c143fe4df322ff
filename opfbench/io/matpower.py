"""MATPOWER version-2 case files (`.m`): the reader, the generators-as-DER mapping and the
writer (`to_ppc`: a Network as a MATPOWER case dict).

Reads `mpc.baseMVA`, `mpc.bus`, `mpc.gen`, `mpc.branch` and `mpc.gencost`, and executes
only the trailing conversions that MATPOWER's distribution cases use (ohm → p.u. for
branch r/x, kW → MW for loads, kVA → MW/MVAr at a fixed power factor). Any other code
line is an error: a case file is data, and we do not guess what unknown code means.

Refused with a `CaseFormatError` naming the file (and matrix, row, column or line): a file
that is not UTF-8 text (a leading byte-order mark is dropped); a matrix defined twice; an
entry that is not a MATLAB number (Python's 1_0 or ١٠ are not) or not finite; a
non-finite or non-positive baseMVA; an ohm → p.u. conversion that over- or underflows;
a status other than 0 or 1; in-service generators at one bus holding different VG; a fractional bus number or bus type; a negative branch resistance (it would make
negative losses and a meaningless loss bound); VMIN > VMAX at a bus; a bus number
outside 1..2^53 − 1 or listed twice; a bus of type 4 (isolated); an in-service generator
with QMAX < QMIN or PMAX < PMIN; a power factor outside (0, 1]; the ohm → p.u.
conversion with a zero or negative BASE_KV at bus row 1. What the network itself
checks (bus types, voltage limits and setpoints, zero impedance, islands) comes back
as a `CaseFormatError` naming the file.

DER from generators (`der=gens` in a case spec, `--der gens` on the command line): every
in-service generator other than the slack's becomes a DER of the generic "inverter" kind
(a solar unit; `opfbench.capability`) at its bus: rated P̄ = PMAX (PG where PMAX ≤ 0),
S̄ = P̄/der_pf (default 0.90), stored output PG; its bus becomes a PQ bus (the DER's Q is
what the strategies set, not a voltage setpoint). A generator with no positive P̄, or
with PG outside [0, P̄], is refused.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from opfbench.errors import CaseFormatError, NetworkError
from opfbench.network import DER, Network

BUS_COLS, GEN_COLS, BRANCH_COLS = 13, 10, 11  # minimum columns MATPOWER v2 requires
MAX_BUS_NUMBER = 2**53 - 1  # the largest whole number a file's floating-point entry holds exactly
_MATRICES = ("bus", "gen", "branch", "gencost")
_NUMBER = re.compile(r"^[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|Inf|inf|NaN|nan)$", re.ASCII)


@dataclass
class MatpowerCase:
    """Raw MATPOWER data after the recognized conversions (MATPOWER units: MW, p.u.)."""

    path: str
    base_mva: float
    bus: np.ndarray
    gen: np.ndarray
    branch: np.ndarray
    gencost: np.ndarray | None


def _strip_comment(line: str) -> str:
    # MATPOWER data never contains '%' inside strings we accept, so cut at the first '%'.
    return line.split("%", 1)[0].strip()


def _norm(statement: str) -> str:
    return re.sub(r"\s+", "", statement)


# Conversion statements recognized after the data blocks (whitespace removed).
_IDX_ASSIGN = re.compile(r"^\[[A-Z_0-9,]+\]=idx_(bus|brch|gen);$")
_VBASE = "Vbase=mpc.bus(1,BASE_KV)*1e3;"
_SBASE = "Sbase=mpc.baseMVA*1e6;"
_OHM_TO_PU = "mpc.branch(:,[BR_RBR_X])=mpc.branch(:,[BR_RBR_X])/(Vbase^2/Sbase);"
_KW_TO_MW = "mpc.bus(:,[PD,QD])=mpc.bus(:,[PD,QD])/1e3;"
_PF_SET = re.compile(r"^pf=([0-9.eE+-]+);$")
_QD_FROM_PF = "mpc.bus(:,QD)=mpc.bus(:,PD)*sin(acos(pf));"
_PD_FROM_PF = "mpc.bus(:,PD)=mpc.bus(:,PD)*pf;"


def _statements(lines: list[tuple[int, str]]) -> list[tuple[int, str]]:
    """Join MATLAB continuation lines (`...`) into statements, keeping the first line number."""
    out: list[tuple[int, str]] = []
    buf, start = "", 0
    for lineno, text in lines:
        if not buf:
            start = lineno
        if text.endswith("..."):
            buf += text[:-3] + " "
            continue
        buf += text
        out.append((start, buf))
        buf = ""
    if buf:
        out.append((start, buf))
    return out


def read_matpower(path: str | Path) -> MatpowerCase:
    """Parse a MATPOWER v2 `.m` file; raise `CaseFormatError` naming file, matrix and row."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except OSError as exc:
        raise CaseFormatError(f"{path}: cannot read case file ({exc.strerror})") from exc
    except UnicodeDecodeError as exc:
        raise CaseFormatError(f"{path}: not a text MATPOWER file (byte {exc.start} is not UTF-8)") from None
    if "\x00" in text:
        raise CaseFormatError(f"{path}: not a text MATPOWER file (contains NUL bytes)")
    text = text.removeprefix("\ufeff")  # a byte-order mark, as some editors write
    name = str(path)
    lines = [(i + 1, _strip_comment(raw)) for i, raw in enumerate(text.splitlines())]
    lines = [(i, s) for i, s in lines if s]

    matrices: dict[str, np.ndarray] = {}
    opened: dict[str, int] = {}  # matrix -> line it is defined at
    base_mva: float | None = None
    trailing: list[tuple[int, str]] = []
    i = 0
    while i < len(lines):
        lineno, s = lines[i]
        m_start = re.match(r"^mpc\.(\w+)\s*=\s*\[(.*)$", s)
        if m_start:
            key = m_start.group(1)
            if key not in _MATRICES:
                raise CaseFormatError(f"{name}, line {lineno}: unsupported matrix mpc.{key}")
            if key in opened:
                raise CaseFormatError(f"{name}, line {lineno}: mpc.{key} is defined a second time (first at line {opened[key]})")
            opened[key] = lineno
            body: list[tuple[int, str]] = []
            rest = m_start.group(2)
            i += 1
            while "]" not in rest:
                if rest.strip():
                    body.append((lineno, rest))
                if i >= len(lines):
                    raise CaseFormatError(f"{name}: mpc.{key} opened at line {lineno} is never closed with '];'")
                lineno, rest = lines[i]
                i += 1
            before, after = rest.split("]", 1)
            if after.strip() not in ("", ";"):  # e.g. ]' (transposed) or ] * 1e3: not data, and not to be guessed
                raise CaseFormatError(
                    f"{name}, line {lineno}: mpc.{key} = [...] is followed by {after.strip()!r}; a matrix ends with '];'"
                )
            if before.strip():
                body.append((lineno, before))
            matrices[key] = _parse_matrix(name, key, body)
            continue
        if re.match(r"^function\s+mpc\s*=\s*\w+$", s) or re.match(r"^mpc\.version\s*=\s*'2'\s*;?$", s):
            i += 1
            continue
        if re.match(r"^mpc\.version\s*=", s):
            raise CaseFormatError(f"{name}, line {lineno}: only MATPOWER case format version '2' is supported")
        m_base = re.match(r"^mpc\.baseMVA\s*=\s*([^;]+);?$", s)
        if m_base:
            try:
                base_mva = float(m_base.group(1))
            except ValueError:
                raise CaseFormatError(f"{name}, line {lineno}: mpc.baseMVA is not a number: {m_base.group(1)!r}") from None
            i += 1
            continue
        trailing.append((lineno, s))
        i += 1

    if base_mva is None:
        raise CaseFormatError(f"{name}: missing mpc.baseMVA")
    if not (np.isfinite(base_mva) and base_mva > 0):
        raise CaseFormatError(f"{name}: mpc.baseMVA must be a finite positive number, got {base_mva}")
    for key in ("bus", "gen", "branch"):
        if key not in matrices:
            raise CaseFormatError(f"{name}: missing mpc.{key}")
    _check_columns(name, "bus", matrices["bus"], BUS_COLS)
    _check_columns(name, "gen", matrices["gen"], GEN_COLS)
    _check_columns(name, "branch", matrices["branch"], BRANCH_COLS)
    branch = matrices["branch"]
    neg_r = np.flatnonzero(branch[:, 2] < 0)
    if neg_r.size:  # checked on the file's values, before any unit conversion
        k = neg_r[0]
        raise CaseFormatError(
            f"{name}: mpc.branch row {k + 1} ({branch[k, 0]:g}-{branch[k, 1]:g}): negative "
            f"resistance BR_R = {branch[k, 2]:g}; it would make negative losses, so it is refused"
        )
    case = MatpowerCase(name, base_mva, matrices["bus"], matrices["gen"], matrices["branch"], matrices.get("gencost"))
    _apply_conversions(case, _statements(trailing))
    return case


def _parse_matrix(name: str, key: str, body: list[tuple[int, str]]) -> np.ndarray:
    rows: list[list[float]] = []
    row_lines: list[int] = []
    for lineno, chunk in body:
        for part in chunk.split(";"):
            tokens = part.replace(",", " ").split()
            if not tokens:
                continue
            values = []
            for col, tok in enumerate(tokens, start=1):
                if not _NUMBER.match(tok):  # MATLAB's number syntax (Python's float() also reads 1_0 and ١٠)
                    raise CaseFormatError(
                        f"{name}: mpc.{key} row {len(rows) + 1} (line {lineno}), column {col}: non-numeric entry {tok!r}"
                    )
                values.append(float(tok))
            rows.append(values)
            row_lines.append(lineno)
    if not rows:
        return np.zeros((0, 0))
    widths = {len(r) for r in rows}
    if len(widths) > 1:
        first = len(rows[0])
        bad = next(k for k, r in enumerate(rows) if len(r) != first)
        raise CaseFormatError(
            f"{name}: mpc.{key} row {bad + 1} (line {row_lines[bad]}) has {len(rows[bad])} columns, row 1 has {first}"
        )
    arr = np.array(rows)
    if not np.all(np.isfinite(arr)):
        r, c = np.argwhere(~np.isfinite(arr))[0]
        raise CaseFormatError(
            f"{name}: mpc.{key} row {r + 1} (line {row_lines[r]}), column {c + 1}: value {arr[r, c]} is not finite"
        )
    return arr


def _check_columns(name: str, key: str, arr: np.ndarray, need: int) -> None:
    if arr.shape[0] == 0:
        raise CaseFormatError(f"{name}: mpc.{key} is empty")
    if arr.shape[1] < need:
        raise CaseFormatError(f"{name}: mpc.{key} has {arr.shape[1]} columns, MATPOWER v2 needs at least {need}")


def _apply_conversions(case: MatpowerCase, statements: list[tuple[int, str]]) -> None:
    """Execute the recognized conversion statements in file order."""
    env: dict[str, float] = {}
    for lineno, stmt in statements:
        s = _norm(stmt)
        if _IDX_ASSIGN.match(s):
            continue
        if s == _VBASE:
            if not case.bus[0, 9] > 0:
                raise CaseFormatError(
                    f"{case.path}, line {lineno}: Vbase from mpc.bus row 1 BASE_KV = {case.bus[0, 9]:g} kV; "
                    "the ohm → p.u. conversion needs a positive base voltage"
                )
            env["Vbase"] = float(case.bus[0, 9]) * 1e3  # a Python float: 1e308 kV overflows to inf quietly, refused below
        elif s == _SBASE:
            env["Sbase"] = case.base_mva * 1e6
        elif s == _OHM_TO_PU:
            if "Vbase" not in env or "Sbase" not in env:
                raise CaseFormatError(f"{case.path}, line {lineno}: ohm→p.u. conversion before Vbase/Sbase are defined")
            ohms = case.branch[:, 2:4].copy()
            with np.errstate(all="ignore"):
                z_base = np.float64(env["Vbase"]) ** 2 / env["Sbase"]  # numpy: overflow gives inf, refused below
                case.branch[:, 2:4] /= z_base
            lost = ~np.isfinite(case.branch[:, 2:4]) | ((case.branch[:, 2:4] == 0) & (ohms != 0))
            if not (np.isfinite(z_base) and z_base > 0) or lost.any():
                raise CaseFormatError(
                    f"{case.path}, line {lineno}: the ohm → p.u. conversion over- or underflows (base impedance "
                    f"{z_base:g} ohm from BASE_KV {case.bus[0, 9]:g} kV and baseMVA {case.base_mva:g}): check those two"
                )
        elif s == _KW_TO_MW:
            case.bus[:, 2:4] /= 1e3
        elif m := _PF_SET.match(s):
            try:
                env["pf"] = float(m.group(1))
            except ValueError:
                raise CaseFormatError(f"{case.path}, line {lineno}: pf is not a number: {m.group(1)!r}") from None
            if not 0 < env["pf"] <= 1:
                raise CaseFormatError(f"{case.path}, line {lineno}: power factor pf = {m.group(1)} must lie in (0, 1]")
        elif s in (_QD_FROM_PF, _PD_FROM_PF):
            if "pf" not in env:
                raise CaseFormatError(f"{case.path}, line {lineno}: power-factor conversion before pf is defined")
            pf = env["pf"]
            if s == _QD_FROM_PF:
                case.bus[:, 3] = case.bus[:, 2] * np.sin(np.arccos(pf))
            else:
                case.bus[:, 2] = case.bus[:, 2] * pf
        else:
            raise CaseFormatError(f"{case.path}, line {lineno}: unrecognized code line: {stmt.strip()!r}")


def to_network(case: MatpowerCase, name: str | None = None) -> Network:
    """Build the shared `Network` from a parsed case; validates bus references and slack."""
    return _network(case, name)[0]


def _network(case: MatpowerCase, name: str | None = None, der_pf: float | None = None) -> tuple[Network, np.ndarray]:
    """(network, stored DER P (n_der,) MW); `der_pf` not None turns the non-slack
    generators into DER (see the module docstring)."""
    label = name or Path(case.path).stem
    bus, gen, branch = case.bus, case.gen, case.branch
    for matrix, arr, cols in (
        ("bus", bus, ((0, "BUS_I"), (1, "BUS_TYPE"))),
        ("branch", branch, ((0, "F_BUS"), (1, "T_BUS"))),
        ("gen", gen, ((0, "GEN_BUS"),)),
    ):
        for col, col_name in cols:
            bad = np.flatnonzero(arr[:, col] != np.round(arr[:, col]))
            if bad.size:
                raise CaseFormatError(
                    f"{case.path}: mpc.{matrix} row {bad[0] + 1}, column {col + 1} ({col_name}): "
                    f"{arr[bad[0], col]:g} is not an integer"
                )
    crossed = np.flatnonzero(bus[:, 12] > bus[:, 11])
    if crossed.size:
        i = crossed[0]
        raise CaseFormatError(
            f"{case.path}: mpc.bus row {i + 1} (bus {bus[i, 0]:.0f}): VMIN {bus[i, 12]:g} > VMAX {bus[i, 11]:g} p.u."
        )
    bad_id = np.flatnonzero((bus[:, 0] < 1) | (bus[:, 0] > MAX_BUS_NUMBER))
    if bad_id.size:
        raise CaseFormatError(
            f"{case.path}: mpc.bus row {bad_id[0] + 1}, column 1 (BUS_I): bus number {bus[bad_id[0], 0]:g} outside "
            f"1..{MAX_BUS_NUMBER} (a positive whole number, exact in the file's floating-point numbers)"
        )
    ids = bus[:, 0].astype(np.int64)
    unique, first = np.unique(ids, return_index=True)
    if unique.size != ids.size:
        row = np.setdiff1d(np.arange(ids.size), first)[0]
        raise CaseFormatError(
            f"{case.path}: mpc.bus row {row + 1} lists bus {ids[row]} again (first at row {np.flatnonzero(ids == ids[row])[0] + 1})"
        )
    pos = {int(b): k for k, b in enumerate(ids)}

    def lookup(matrix: str, row: int, col_name: str, bus_id: float) -> int:
        if int(bus_id) not in pos:
            raise CaseFormatError(f"{case.path}: mpc.{matrix} row {row + 1}: {col_name} {int(bus_id)} is not a bus in mpc.bus")
        return pos[int(bus_id)]

    f = np.array([lookup("branch", k, "from bus", v) for k, v in enumerate(branch[:, 0])], dtype=int)
    t = np.array([lookup("branch", k, "to bus", v) for k, v in enumerate(branch[:, 1])], dtype=int)
    gbus = np.array([lookup("gen", k, "bus", v) for k, v in enumerate(gen[:, 0])], dtype=int)

    bad_type = np.flatnonzero(~np.isin(bus[:, 1], (1, 2, 3, 4)))
    if bad_type.size:
        raise CaseFormatError(
            f"{case.path}: mpc.bus row {bad_type[0] + 1}: unknown bus type {bus[bad_type[0], 1]:g} "
            "(1 PQ, 2 PV, 3 reference, 4 isolated)"
        )
    btype = bus[:, 1].astype(int)
    slacks = np.flatnonzero(btype == 3)
    if slacks.size != 1:
        raise CaseFormatError(f"{case.path}: mpc.bus needs exactly one reference bus (type 3), found {slacks.size}")
    slack = int(slacks[0])
    for matrix, arr, col, col_name in (("branch", branch, 10, "BR_STATUS"), ("gen", gen, 7, "GEN_STATUS")):
        bad = np.flatnonzero(~np.isin(arr[:, col], (0, 1)))
        if bad.size:
            raise CaseFormatError(
                f"{case.path}: mpc.{matrix} row {bad[0] + 1}, column {col + 1} ({col_name}): {arr[bad[0], col]:g}; "
                "a status is 1 (in service) or 0 (out of service)"
            )
    _check_isolated(case, btype, f, t, branch[:, 10] > 0)
    gen_on = gen[:, 7] > 0
    _check_gen_limits(case, gen, gen_on)
    _check_gen_voltages(case, gen, gen_on, gbus)
    slack_gens = np.flatnonzero(gen_on & (gbus == slack))
    if slack_gens.size == 0:
        raise CaseFormatError(f"{case.path}: no in-service generator at the reference bus {ids[slack]}")
    others = np.flatnonzero(gen_on & (gbus != slack))
    ders, der_p = _gens_as_ders(case, gbus, others, der_pf) if der_pf is not None else ((), np.zeros(0))
    if der_pf is not None:
        others = others[:0]
    # PV buses without an in-service generator behave as PQ buses (MATPOWER does the same).
    btype = btype.copy()
    btype[(btype == 2) & ~np.isin(np.arange(len(ids)), gbus[others])] = 1
    r, x = branch[:, 2], branch[:, 3]
    status = branch[:, 10] > 0
    tap = np.where(branch[:, 8] == 0, 1.0, branch[:, 8])
    try:
        net = Network(
            name=label,
            base_mva=case.base_mva,
            bus_ids=ids,
            bus_type=btype,
            base_kv=bus[:, 9].copy(),
            load_p_mw=bus[:, 2].copy(),
            load_q_mvar=bus[:, 3].copy(),
            gs_mw=bus[:, 4].copy(),
            bs_mvar=bus[:, 5].copy(),
            vmin=bus[:, 12].copy(),
            vmax=bus[:, 11].copy(),
            f=f,
            t=t,
            r=r.copy(),
            x=x.copy(),
            b=branch[:, 4].copy(),
            tap=tap,
            shift=branch[:, 9].copy(),
            status=status,
            slack=slack,
            v_slack=float(gen[slack_gens[0], 5]),
            gen_bus=gbus[others],
            gen_p_mw=gen[others, 1].copy(),
            gen_q_mvar=gen[others, 2].copy(),
            gen_vset=gen[others, 5].copy(),
            ders=ders,
        )
    except NetworkError as exc:
        raise CaseFormatError(f"{case.path}: {exc}") from None
    return net, der_p


def _check_isolated(case: MatpowerCase, btype: np.ndarray, f: np.ndarray, t: np.ndarray, on: np.ndarray) -> None:
    """MATPOWER's bus type 4 (isolated) is refused: wired in by an in-service branch it
    contradicts itself; left alone it would be an island (MATPOWER drops such buses —
    we do not guess which the file meant)."""
    isolated = np.flatnonzero(btype == 4)
    if not isolated.size:
        return
    i = isolated[0]
    rows = np.flatnonzero(on & ((f == i) | (t == i))) + 1
    bus_id = f"{case.bus[i, 0]:.0f}"
    if rows.size:
        raise CaseFormatError(
            f"{case.path}: mpc.bus row {i + 1}: bus {bus_id} has type 4 (isolated) but in-service mpc.branch row(s) "
            f"{', '.join(map(str, rows[:10]))} connect it; give it type 1 (PQ) or take those branches out of service"
        )
    raise CaseFormatError(
        f"{case.path}: mpc.bus row {i + 1}: bus {bus_id} has type 4 (isolated); remove the bus (and its out-of-service "
        "branches and generators) from the case: a study network has no isolated buses"
    )


def _check_gen_limits(case: MatpowerCase, gen: np.ndarray, on: np.ndarray) -> None:
    """In-service generators need QMAX ≥ QMIN and PMAX ≥ PMIN."""
    for hi, lo, label in ((3, 4, "Q"), (8, 9, "P")):
        crossed = np.flatnonzero(on & (gen[:, hi] < gen[:, lo]))
        if crossed.size:
            g = crossed[0]
            raise CaseFormatError(
                f"{case.path}: mpc.gen row {g + 1} (bus {gen[g, 0]:.0f}): {label}MAX {gen[g, hi]:g} < {label}MIN {gen[g, lo]:g}"
            )


def _check_gen_voltages(case: MatpowerCase, gen: np.ndarray, on: np.ndarray, gbus: np.ndarray) -> None:
    """In-service generators at the same bus hold one voltage (VG): two different ones
    leave it to the reading program which wins (MATPOWER: the last)."""
    first: dict[int, int] = {}
    for g in np.flatnonzero(on):
        k = first.setdefault(int(gbus[g]), int(g))
        if gen[g, 5] != gen[k, 5]:
            raise CaseFormatError(
                f"{case.path}: mpc.gen rows {k + 1} and {g + 1} (bus {gen[g, 0]:.0f}) hold different voltages VG "
                f"{gen[k, 5]:g} and {gen[g, 5]:g} p.u.; give them one"
            )


def load_case_file(path: str | Path, name: str | None = None) -> Network:
    """Read a MATPOWER `.m` file straight into a `Network`."""
    return to_network(read_matpower(path), name)


def _gens_as_ders(case: MatpowerCase, gbus: np.ndarray, rows: np.ndarray, der_pf: float) -> tuple[tuple[DER, ...], np.ndarray]:
    """The generators `rows` as inverter DER (see the module docstring) and their PG."""
    if not 0 < der_pf <= 1:
        raise CaseFormatError(f"{case.path}: der-pf must lie in (0, 1], got {der_pf}")
    ders, stored = [], []
    for k in rows:
        pg, pmax = float(case.gen[k, 1]), float(case.gen[k, 8])
        rating = pmax if pmax > 0 else pg
        if not rating > 0:
            raise CaseFormatError(f"{case.path}: mpc.gen row {k + 1}: PMAX {pmax:g} and PG {pg:g} MW give no positive DER rating")
        if not -1e-9 <= pg <= rating * (1 + 1e-9):
            raise CaseFormatError(f"{case.path}: mpc.gen row {k + 1}: PG {pg:g} MW outside [0, PMAX = {rating:g}] MW")
        ders.append(DER(int(gbus[k]), "inverter", rating, rating / der_pf, "solar"))
        stored.append(min(max(pg, 0.0), rating))
    return tuple(ders), np.array(stored, dtype=float)


def read_case_file(path: str | Path, name: str | None = None, der_pf: float | None = None) -> tuple[Network, np.ndarray]:
    """(network, stored DER P) of a MATPOWER `.m` file; `der_pf` not None maps its
    non-slack generators to DER with S̄ = P̄/der_pf."""
    return _network(read_matpower(path), name, der_pf)


def to_ppc(net: Network) -> dict:
    """MATPOWER version-2 case dict of `net` at nominal load: the slack generator
    (unbounded P/Q) first, then the case's fixed generators (P, Q, voltage setpoint),
    branches as in-service/out-of-service π models. DERs are not included. A branch's
    shunt conductance g (a transformer's iron losses) has no MATPOWER column: it is
    written as bus shunt conductance GS at both ends (g/2 at the to end, g/2/tap² at the
    from end: the same power flow; MATPOWER counts it as shunt, not branch, losses)."""
    n = net.n_bus
    bus = np.zeros((n, 13))
    bus[:, 0] = np.arange(1, n + 1)
    bus[:, 1] = net.bus_type
    bus[:, 2], bus[:, 3] = net.load_p_mw, net.load_q_mvar
    bus[:, 4], bus[:, 5] = net.gs_mw, net.bs_mvar
    if net.g.any():
        on = net.status.astype(float)
        np.add.at(bus[:, 4], net.f, on * net.g / 2 / net.tap**2 * net.base_mva)
        np.add.at(bus[:, 4], net.t, on * net.g / 2 * net.base_mva)
    bus[:, 6], bus[:, 7], bus[:, 9], bus[:, 10] = 1, 1.0, net.base_kv, 1
    bus[:, 11], bus[:, 12] = net.vmax, net.vmin
    gen = np.zeros((1 + len(net.gen_bus), 21))
    # bus, Pg, Qg, Qmax, Qmin, Vg, mBase, status, Pmax, Pmin
    cols = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9]
    gen[0, cols] = [net.slack + 1, 0, 0, 1e4, -1e4, net.v_slack, net.base_mva, 1, 1e4, -1e4]
    for row, (b, p, q, vset) in enumerate(zip(net.gen_bus, net.gen_p_mw, net.gen_q_mvar, net.gen_vset, strict=True), start=1):
        gen[row, cols] = [b + 1, p, q, 1e4, -1e4, vset, net.base_mva, 1, p, p]
    branch = np.zeros((net.n_branch, 13))
    branch[:, 0], branch[:, 1] = net.f + 1, net.t + 1
    branch[:, 2], branch[:, 3], branch[:, 4] = net.r, net.x, net.b
    branch[:, 8] = np.where(net.tap == 1.0, 0.0, net.tap)
    branch[:, 9] = net.shift
    branch[:, 10] = net.status
    branch[:, 11], branch[:, 12] = -360, 360
    return {"version": "2", "baseMVA": net.base_mva, "bus": bus, "gen": gen, "branch": branch}
