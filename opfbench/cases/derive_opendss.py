"""Copy the shipped OpenDSS feeders from the raw test cases into the package.

    python -m opfbench.cases.derive_opendss --source /path/to/shared/data/opendss [--out DIR]

``--source`` is the folder holding ``IEEETestCases/`` and ``EPRITestCircuits/`` (DSS-
Extensions' ``electricdss-tst``, ``Version8/Distrib``, BSD-3); ``--out`` defaults to the
package's ``cases/opendss/`` folder. Each feeder's master file and the files it reads are
copied unchanged into a folder of its own (`FEEDERS` lists them; `SHARED` the files they
read from their parent folder), with the licence and a
PROVENANCE.md of every file's SHA-256. The copy is then checked: OpenDSS compiles each
copied master on its own and solves the same snapshot, node for node, as the original —
a file missing from the list fails here, not at run time. Never run at import or load time.
"""

from __future__ import annotations

import argparse
import hashlib
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from opfbench.cases.opendss_cases import OPENDSS_CASES
from opfbench.errors import OpfbenchError

FOLDER = Path(__file__).resolve().parent / "opendss"
SHARED = ("IEEETestCases/IEEELineCodes.DSS",)
"""Raw files several feeders read from their parent folder (`redirect ../IEEELineCodes.DSS`):
copied to the top of the output folder, the feeders' folders' parent."""
LVTEST_PROFILES = tuple(f"Daily_1min_100profiles/load_profile_{i}.txt" for i in range(1, 101))
FEEDERS: dict[str, tuple[str, tuple[str, ...]]] = {
    # name: (raw folder, files: the master first)
    "ieee13": ("IEEETestCases/13Bus", ("IEEE13Nodeckt.dss", "IEEELineCodes.DSS", "IEEE13Node_BusXY.csv")),
    "ieee34": ("IEEETestCases/34Bus", ("ieee34Mod1.dss", "IEEELineCodes.DSS")),
    "ieee37": ("IEEETestCases/37Bus", ("ieee37.dss", "IEEELineCodes.DSS", "IEEE37_BusXY.csv")),
    "ieee123": (
        "IEEETestCases/123Bus",
        ("IEEE123Master.dss", "IEEELineCodes.DSS", "IEEE123Regulators.DSS", "IEEE123Loads.DSS"),
    ),
    "eulv": (
        "IEEETestCases/LVTestCase",
        (
            "Master.dss",
            "LineCode.txt",
            "LoadShapes.txt",
            "Lines.txt",
            "Transformers.txt",
            "Loads.txt",
            "Monitors.txt",
            "Buscoords.txt",
            *LVTEST_PROFILES,
        ),
    ),
    "ieee8500": (
        "IEEETestCases/8500-Node",
        (
            "Master.dss",
            "LineCodes2.DSS",
            "Triplex_Linecodes.dss",
            "Lines.dss",
            "Transformers.dss",
            "LoadXfmrCodes.dss",
            "Triplex_Lines.DSS",
            "Loads.dss",
            "Capacitors.dss",
            "CapControls.DSS",
            "Regulators.dss",
            "Buscoords.dss",
        ),
    ),
    "ckt5": (
        "EPRITestCircuits/ckt5",
        (
            "Master_ckt5.dss",
            "WireData_ckt5.dss",
            "LineGeometry_ckt5.dss",
            "LineCodes_ckt5.dss",
            "Lines_ckt5.dss",
            "Transformers_ckt5.dss",
            "Loadshapes_ckt5.dss",
            "Loads_ckt5.dss",
            "XFR_Loads_ckt5.dss",
            "Capacitors_ckt5.dss",
            "Regulators_ckt5.dss",
            "Generators_ckt5.dss",
            "Buscoords_ckt5.dss",
        ),
    ),
    "ckt7": (
        "EPRITestCircuits/ckt7",
        (
            "Master_ckt7.dss",
            "Loadshapes_ckt7.dss",
            "Substation_ckt7.dss",
            "LineCodes_ckt7.dss",
            "Lines_ckt7.dss",
            "Services_ckt7.dss",
            "Load_XFMR_ckt7.dss",
            "Loads_ckt7.dss",
            "Capacitors_ckt7.dss",
            "AllocationFactors.dss",
            "BusCoords_ckt7.dss",
        ),
    ),
    "ckt24": (
        "EPRITestCircuits/ckt24",
        (
            "master_ckt24.dss",
            "Wiredata_ckt24.dss",
            "Linegeometry_ckt24.dss",
            "Linecodes_ckt24.dss",
            "TriplexLineCodes_ckt24.dss",
            "substation_ckt24.dss",
            "LS_PhaseA.txt",
            "LS_PhaseB.txt",
            "LS_PhaseC.txt",
            "LS_ThreePhase.txt",
            "Other_Bus_Load.txt",
            "lines_ckt24.dss",
            "capacitors_ckt24.dss",
            "stepxfmrs_ckt24.dss",
            "transformers_ckt24.dss",
            "sec_serv_ckt24.dss",
            "Allocated_Loads_ckt24.dss",
            "Other_Load_ckt24.dss",
            "AllocationFactors_Base.Txt",
            "Monitors_ckt24.dss",
            "buscoords_ckt24.dss",
        ),
    ),
}


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _snapshot(master: Path) -> tuple[list[str], np.ndarray]:
    """OpenDSS's node names and solved node voltages of `master` (compiled in its folder)."""
    import opendssdirect as dss

    dss.Basic.AllowChangeDir(False)
    dss.Text.Command("clear")
    dss.Text.Command(f'compile "{master}"')
    dss.Text.Command("set mode=snapshot maxiterations=100 tolerance=1e-10")
    dss.Solution.Solve()
    if not dss.Solution.Converged():
        raise OpfbenchError(f"{master}: OpenDSS's snapshot does not converge")
    return list(dss.Circuit.AllNodeNames()), np.asarray(dss.Circuit.AllBusVolts())


def derive(source: Path, out: Path) -> list[str]:
    """Copy every feeder of FEEDERS from `source` into `out`, check each copy against its
    original, write LICENSE.txt and PROVENANCE.md; returns the PROVENANCE rows."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        staging = Path(tmp) / "opendss"
        staging.mkdir()
        for rel in SHARED:
            shutil.copyfile(source / rel, staging / Path(rel).name)
            rows.append(f"| `{Path(rel).name}` | `{rel}` | {_sha256(staging / Path(rel).name)} |")
        for name, (folder, files) in FEEDERS.items():
            if OPENDSS_CASES[name][1] != files[0]:
                raise OpfbenchError(f"{name}: FEEDERS' master {files[0]} is not opendss_cases' {OPENDSS_CASES[name][1]}")
            for rel in files:
                src = source / folder / rel
                if not src.is_file():
                    raise OpfbenchError(f"{src}: not found (is --source the opendss/ folder?)")
                dst = staging / name / rel
                dst.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(src, dst)
                rows.append(f"| `{name}/{rel}` | `{folder}/{rel}` | {_sha256(dst)} |")
            names, volts = _snapshot(staging / name / files[0])
            ref_names, ref_volts = _snapshot(source / folder / files[0])
            if names != ref_names or not np.array_equal(volts, ref_volts):
                raise OpfbenchError(f"{name}: the copied feeder does not solve as the original (a file missing from FEEDERS?)")
            print(f"{name}: {len(files)} files, {len(names)} nodes, same snapshot as the original", file=sys.stderr)
        shutil.copyfile(source / "LICENSE.txt", staging / "LICENSE.txt")
        (staging / "PROVENANCE.md").write_text(_provenance(rows), encoding="utf-8")
        if out.exists():
            shutil.rmtree(out)
        shutil.copytree(staging, out)
    return rows


def _provenance(rows: list[str]) -> str:
    return "\n".join(
        [
            "# Shipped OpenDSS feeders",
            "",
            "Copied unchanged by `python -m opfbench.cases.derive_opendss --source <shared/data/opendss>` from the",
            "OpenDSS distribution test cases as kept by DSS-Extensions (`electricdss-tst`, commit 3b20839,",
            "folder `Version8/Distrib`), licensed BSD-3 (`LICENSE.txt`, copied verbatim). Each feeder's folder",
            "holds its master file and every file the master reads; the derivation checks that OpenDSS",
            "solves each copy to the same snapshot as the original. Nothing reads the raw folder at run time.",
            "",
            "Feeders: IEEE 13, 34 (Mod 1), 37 and 123 node test feeders; the IEEE European LV test feeder",
            "(`eulv`: 55 houses with 100 one-minute household load shapes); the IEEE 8500-node feeder",
            "(balanced loads); EPRI test circuits ckt5, ckt7 and ckt24 (ckt24 with its 8760-h load shapes).",
            "",
            "| file | raw file | sha256 |",
            "|---|---|---|",
            *rows,
            "",
        ]
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m opfbench.cases.derive_opendss", description=__doc__.splitlines()[0])
    parser.add_argument("--source", type=Path, required=True, help="the raw opendss/ folder")
    parser.add_argument("--out", type=Path, default=FOLDER, help=f"output folder (default {FOLDER})")
    args = parser.parse_args(argv)
    try:
        rows = derive(args.source, args.out)
    except OpfbenchError as exc:
        print(f"derive_opendss: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {len(rows)} files to {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
