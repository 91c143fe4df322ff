"""MATPOWER case texts the reader, power-flow and error tests write to files."""

#: A valid 3-bus radial case in ohms and kW with the trailing ohm→p.u. and kW→MW
#: conversions of the case33bw file; the error tests mutate one field of it at a time.
TINY_CASE = """function mpc = tiny
mpc.version = '2';
mpc.baseMVA = 10;
mpc.bus = [
\t1\t3\t0\t0\t0\t0\t1\t1\t0\t12.66\t1\t1\t1;
\t2\t1\t100\t60\t0\t0\t1\t1\t0\t12.66\t1\t1.1\t0.9;
\t3\t1\t90\t40\t0\t0\t1\t1\t0\t12.66\t1\t1.1\t0.9;
];
mpc.gen = [
\t1\t0\t0\t10\t-10\t1\t100\t1\t10\t0\t0\t0\t0\t0\t0\t0\t0\t0\t0\t0\t0;
];
mpc.branch = [
\t1\t2\t0.0922\t0.0470\t0\t0\t0\t0\t0\t0\t1\t-360\t360;
\t2\t3\t0.4930\t0.2511\t0\t0\t0\t0\t0\t0\t1\t-360\t360;
];
mpc.gencost = [
\t2\t0\t0\t3\t0\t20\t0;
];
[PQ, PV, REF, NONE, BUS_I, BUS_TYPE, PD, QD, GS, BS, BUS_AREA, VM, ...
    VA, BASE_KV, ZONE, VMAX, VMIN, LAM_P, LAM_Q, MU_VMAX, MU_VMIN] = idx_bus;
[F_BUS, T_BUS, BR_R, BR_X, BR_B, RATE_A, RATE_B, RATE_C, ...
    TAP, SHIFT, BR_STATUS, PF, QF, PT, QT, MU_SF, MU_ST, ...
    ANGMIN, ANGMAX, MU_ANGMIN, MU_ANGMAX] = idx_brch;
Vbase = mpc.bus(1, BASE_KV) * 1e3;      %% in Volts
Sbase = mpc.baseMVA * 1e6;              %% in VA
mpc.branch(:, [BR_R BR_X]) = mpc.branch(:, [BR_R BR_X]) / (Vbase^2 / Sbase);
mpc.bus(:, [PD, QD]) = mpc.bus(:, [PD, QD]) / 1e3;
"""


#: 4 buses, one voltage-controlled (PV) bus 400 at 1.05 p.u. behind an off-nominal tap.
CASE4_PV = """function mpc = case4pv
mpc.version = '2';
mpc.baseMVA = 1;
mpc.bus = [
\t1\t3\t0\t0\t0\t0\t1\t1\t0\t12.5\t1\t1.1\t0.9;
\t2\t1\t0.4\t0.2\t0\t0\t1\t1\t0\t12.5\t1\t1.1\t0.9;
\t3\t1\t0.4\t0.2\t0\t0\t1\t1\t0\t12.5\t1\t1.1\t0.9;
\t400\t2\t0.4\t0.2\t0\t0\t1\t1\t0\t12.5\t1\t1.1\t0.9;
];
mpc.gen = [
\t1\t0\t0\t10\t-10\t1.0\t100\t1\t10\t0;
\t400\t0.2\t0\t10\t-10\t1.05\t100\t1\t10\t0;
];
mpc.branch = [
\t2\t3\t0.003\t0.006\t0\t0\t0\t0\t0\t0\t1;
\t1\t2\t0.003\t0.006\t0\t0\t0\t0\t0\t0\t1;
\t400\t1\t0.003\t0.006\t0\t0\t0\t0\t1.025\t0\t1;
];
"""


def with_entry(text: str, matrix: str, row_id: float, column: int, value: str) -> str:
    """`text` with column `column` (1-based, as MATPOWER counts) of the `mpc.<matrix>` rows
    whose first entry is `row_id` set to `value`."""
    out, inside = [], False
    for line in text.split("\n"):
        if line.startswith(f"mpc.{matrix} = ["):
            inside = True
        elif inside and line.startswith("];"):
            inside = False
        elif inside and line.startswith("\t"):
            cols = line.rstrip(";").split("\t")
            if float(cols[1]) == row_id:
                cols[column] = value
                line = "\t".join(cols) + ";"
        out.append(line)
    return "\n".join(out)
