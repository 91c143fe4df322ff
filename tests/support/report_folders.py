"""Small contract-conforming run and fault folders with synthetic, plausible numbers, for
the report tests (cheap and deterministic; the real runner writes the same files)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from opfbench.jsonio import write_json
from opfbench.registry.catalog import get_strategy

STRATEGIES = ("no-action", "llma", "lfma", "acopf", "acopf-paper", "socp")
FORMULATIONS = ("acopf", "acopf-paper", "socp")
KS = (0.0, 0.4, 0.8)
NIGHT_MODES = ("connected", "disconnected", "connected-q")
DER = ((10, "PV"), (16, "PV"), (19, "PV"), (27, "DFIG"), (29, "PV"))
# share of the no-action losses each strategy removes at k = 0 (LFMA beats the OPF here, as in the paper)
SAVED = {"no-action": 0.0, "llma": 0.03, "lfma": 0.22, "acopf": 0.20, "acopf-paper": 0.12, "socp": 0.21}


def _time(steps: int, step_min: float) -> pd.DatetimeIndex:
    return pd.date_range("2016-06-28", periods=steps, freq=f"{step_min:g}min", tz="Europe/Copenhagen")


def steps_table(case: str = "paper33", steps: int = 144, step_min: float = 10.0) -> pd.DataFrame:
    time = _time(steps, step_min)
    hour = (time.hour + time.minute / 60).to_numpy()
    night = (hour >= 20) | (hour < 5)
    base = 8.0 + 3.0 * np.sin(np.pi * (hour - 6) / 14).clip(0) + 1.5 * np.cos(2 * np.pi * (hour - 19) / 24)
    bound = base * (1 - 0.23)
    rng = np.random.default_rng(0)
    frames = []
    for mode in NIGHT_MODES:
        for k in KS:
            for name in STRATEGIES:
                for forecast in ("off", "oracle") if get_strategy(name).uses_forecast else ("off",):  # as the runner
                    saved = SAVED[name] * (1 - k) * (1.15 if forecast == "oracle" else 1.0)
                    at_night = {"connected": 0.6, "disconnected": 0.0, "connected-q": 1.2}[mode]
                    frac = np.where(night, saved * at_night, saved)
                    losses = base * (1 + (0.01 if mode == "disconnected" else 0.0)) * (1 - frac)
                    status = np.full(steps, "ok", dtype=object)
                    iterations = np.full(steps, np.nan)
                    solver_ms = np.full(steps, np.nan)
                    solver_status, certified = "", ""
                    if name in FORMULATIONS:
                        iterations = rng.integers(8, 30, steps).astype(float)
                        solver_ms = rng.gamma(4.0, 6.0, steps)
                        certified = "socp" if name == "socp" else "ipopt"
                        if name == "acopf-paper":
                            failed = rng.random(steps) < 0.3
                            status[failed] = np.where(rng.random(int(failed.sum())) < 0.5, "infeasible", "solver-failed")
                            losses = np.where(failed, base * (1 + (0.01 if mode == "disconnected" else 0.0)), losses)
                        if name == "acopf":
                            status[rng.random(steps) < 0.05] = "fallback-cold"
                    frames.append(
                        pd.DataFrame(
                            {
                                "case": case,
                                "strategy": name,
                                "k": k,
                                "night_mode": mode,
                                "forecast": forecast,
                                "time": time,
                                "step_h": step_min / 60,
                                "night": night,
                                "status": status,
                                "losses_kw": losses,
                                "vmin_pu": 0.93 + 0.02 * frac + 0.005 * np.sin(hour),
                                "vmax_pu": 1.0 + 0.01 * frac,
                                "voltage_violation_pu": 0.0,
                                "q_total_mvar": 1.5 * frac,
                                "excursion_mvar": np.where(forecast == "oracle", 0.002 * frac, 0.0),
                                "lower_bound_kw": bound,
                                "power_flows": 1 if name not in FORMULATIONS else 2,
                                "wall_ms": 0.1 if name not in FORMULATIONS else 20.0,
                                "solver_ms": solver_ms,
                                "iterations": iterations,
                                "certified_by": np.where(status == "ok", certified, ""),
                                "fallback": np.where(status == "ok", "", "no-action") if name in FORMULATIONS else "",
                                "solver_status": np.where(status == "ok", "Solve_Succeeded", "Infeasible_Problem_Detected")
                                if name in FORMULATIONS
                                else solver_status,
                            }
                        )
                    )
    return pd.concat(frames, ignore_index=True)


def summary_table(steps: pd.DataFrame) -> pd.DataFrame:
    keys = ["case", "strategy", "k", "night_mode", "forecast"]
    g = steps.assign(
        energy=steps.losses_kw * steps.step_h,
        bound=steps.lower_bound_kw * steps.step_h,
        viol=steps.voltage_violation_pu > 1e-6,
        exc=steps.excursion_mvar > 1e-9,
        bad=steps.status != "ok",
        cert=steps.certified_by != "",
    ).groupby(keys, sort=False)
    out = pd.DataFrame(
        {
            "steps": g.size(),
            "hours": g["step_h"].sum(),
            "avg_loss_kw": g["losses_kw"].mean(),
            "energy_kwh": g["energy"].sum(),
            "not_ok_steps": g["bad"].sum(),
            "voltage_violation_steps": g["viol"].sum(),
            "vmin_pu": g["vmin_pu"].min(),
            "vmax_pu": g["vmax_pu"].max(),
            "max_excursion_mvar": g["excursion_mvar"].max(),
            "excursion_steps": g["exc"].sum(),
            "lower_bound_kwh": g["bound"].sum(),
            "wall_s": g["wall_ms"].sum() / 1e3,
            "solver_s": g["solver_ms"].sum() / 1e3,
            "certified_share": g["cert"].mean(),
        }
    ).reset_index()
    base = out[(out.strategy == "no-action") & (out.forecast == "off")].set_index(["case", "k", "night_mode"])["energy_kwh"]
    out["no_action_kwh"] = out.join(base.rename("na"), on=["case", "k", "night_mode"])["na"]
    out["savings_pct"] = 100 * (1 - out.energy_kwh / out.no_action_kwh)
    out["gap_kwh"] = out.energy_kwh - out.lower_bound_kwh
    out["gap_pct"] = 100 * out.gap_kwh / out.lower_bound_kwh
    return out


def write_run(directory: Path, case: str = "paper33", detail: bool = True, period: str = "paper-day") -> Path:
    """A run folder per docs/CONTRACTS.md (manifest, steps, summary, der_q, bus_v)."""
    directory.mkdir(parents=True, exist_ok=True)
    steps = steps_table(case)
    steps.to_parquet(directory / "steps.parquet", index=False)
    summary_table(steps).to_csv(directory / "summary.csv", index=False)
    time = steps.time.unique()
    if detail:
        keys = steps[["case", "strategy", "k", "night_mode", "forecast", "time", "q_total_mvar", "vmin_pu"]]
        der = pd.DataFrame({"bus": [b for b, _ in DER], "kind": [kd for _, kd in DER]})
        q = keys.merge(der, how="cross").assign(q_mvar=lambda f: f.q_total_mvar / len(DER))
        q.drop(columns=["q_total_mvar", "vmin_pu"]).to_parquet(directory / "der_q.parquet", index=False)
        v = keys.merge(pd.DataFrame({"bus": np.arange(1, 34)}), how="cross")
        v = v.assign(v_pu=1.0 - (1.0 - v.vmin_pu) * v.bus.clip(upper=18) / 18)
        v.drop(columns=["q_total_mvar", "vmin_pu"]).to_parquet(directory / "bus_v.parquet", index=False)
    write_json(
        directory / "manifest.json",
        {
            "schema": 1,
            "opfbench_version": "0.1.0",
            "git_commit": "0123abc",
            "command": ["opfbench", "run"],
            "created_utc": "2026-11-23T19:00:00+00:00",
            "config": {
                "cases": [case],
                "strategies": list(STRATEGIES),
                "ks": list(KS),
                "night_modes": list(NIGHT_MODES),
                "night": "20:00-05:00",
                "forecast": ["off", "oracle"],
                "period": period,
                "step_minutes": 10.0,
                "price_per_kwh": 0.25,
                "currency": "EUR",
                "price_source": "fixture",
                "chunk": "day",
                "detail": detail,
            },
            "period": {"start": str(time[0]), "end": str(time[-1]), "steps": len(time), "step_h": 1 / 6},
            "data_sources": ["BSRN Payerne (PV, 1 min)", "SimBench (load, wind)"],
            "versions": {"python": "3.11", "numpy": "x", "pandas": "x"},
            "machine": {"cores": 2, "platform": "linux"},
            "cases": {
                case: {
                    "buses": 33,
                    "ders": [{"bus": b, "kind": kd, "rating_mw": 0.6} for b, kd in DER],
                    "vmin_pu": 0.9,
                    "vmax_pu": 1.1,
                }
            },
            "tasks": [],
            "timings": {"wall_s": 12.5, "workers": 2, "scheduler": None, "peak_rss_mb": 321.0, "worker_peak_rss_mb": 654.0},
        },
    )
    return directory


def write_fault(directory: Path, case: str = "paper33") -> Path:
    """A fault folder per the fault-folder contract: recovery grows with LLMA/LFMA, shrinks with k."""
    directory.mkdir(parents=True, exist_ok=True)
    added = {"no-action": 0.0, "llma": 8.0, "lfma": 18.0}
    rows, traces = [], []
    t = np.arange(0, 1.0, 0.005)
    for fault_bus in (10, 27):
        for name, extra in added.items():
            for k in KS:
                for variant in ("reference", "stiff-source"):
                    rec = 480.0 + extra * (1 - k) + (3 * fault_bus / 27) - (40 if variant != "reference" else 0)
                    for bus in sorted({b for b, _ in DER} | {fault_bus}):
                        rows.append(
                            {
                                "case": case,
                                "fault_bus": fault_bus,
                                "strategy": name,
                                "k": k,
                                "forecast": "off",
                                "variant": variant,
                                "source_impedance_pu": 0.05,
                                "emf": "reset",
                                "motor_share": 0.3,
                                "bus": bus,
                                "recovery_ms": rec - (5 if bus != fault_bus else 0),
                                "status": "recovered",
                                "vmin_pu": 0.3,
                                "margin_pu": 0.05,
                                "motors_stalled": 0,
                                "sim_ms": 40.0,
                                "der_bus": bus != fault_bus or bus in dict(DER),
                                "faulted": bus == fault_bus,
                            }
                        )
                        v = np.where(t < 0.1, 1.0, np.where(t < 0.1 + rec / 1e3, 0.5 + 0.4 * (t - 0.1) / (rec / 1e3), 0.97))
                        traces.append(
                            pd.DataFrame(
                                {
                                    "case": case,
                                    "fault_bus": fault_bus,
                                    "strategy": name,
                                    "k": k,
                                    "forecast": "off",
                                    "variant": variant,
                                    "bus": bus,
                                    "t_s": t,
                                    "v_pu": v,
                                    "q_mvar": np.where((t > 0.1) & (t < 0.6), 0.6 * (1 - k / 2), 0.1)
                                    if bus in dict(DER)
                                    else np.nan,
                                }
                            )
                        )
    pd.DataFrame(rows).to_parquet(directory / "fault.parquet", index=False)
    pd.concat(traces, ignore_index=True).to_parquet(directory / "traces.parquet", index=False)
    write_json(directory / "manifest.json", {"schema": 1, "command": ["opfbench", "fault", case]})
    return directory
