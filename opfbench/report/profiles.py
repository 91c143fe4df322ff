"""The voltage profile of a three-phase feeder at a run's worst-voltage step: every phase
node's |V| against its bus's distance from the source (OpenDSS's `plot profile`).

The run's tables hold per-step extremes, not node voltages, so the profile is the one
power flow of that step rebuilt from the run's own definition — the case, the period and
its night hours as the manifest gives them — in the no-action state (no DER sets Q; the
DER deliver the P the period gives them): the state every rule starts from. The worst
step is the no-action configuration's step (reference setting: night connected, forecast
off, smallest k) whose |V| lies farthest from 1 p.u."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from opfbench.registry.references import BASELINE

PHASES = (1, 2, 3)


@dataclass(frozen=True)
class Profile:
    """A feeder's profile at one step: per phase (1, 2, 3) the segments from each bus's
    upstream bus to it — x (km) and |V| (p.u.) with None between segments —, the band, the
    step and its extremes."""

    case: str
    time: pd.Timestamp
    segments: dict[int, tuple[list, list]]
    band: tuple[float, float]
    vmin: float
    vmax: float


def worst_step(steps: pd.DataFrame, case: str) -> pd.Timestamp | None:
    """The no-action configuration's step of `case` whose |V| lies farthest from 1 p.u."""
    sub = steps[(steps["case"] == case) & (steps["strategy"] == BASELINE) & (steps["forecast"] == "off")]
    if sub.empty:
        return None
    modes = list(sub["night_mode"].unique())
    sub = sub[sub["night_mode"] == ("connected" if "connected" in modes else modes[0])]
    sub = sub[np.isclose(sub["k"], sub["k"].min())]
    deviation = np.fmax(sub["vmax_pu"] - 1.0, 1.0 - sub["vmin_pu"])
    if not np.isfinite(deviation).any():
        return None
    return pd.Timestamp(sub["time"].iloc[int(np.nanargmax(deviation.to_numpy()))])


def profile(manifest: dict, steps: pd.DataFrame, case: str) -> Profile | None:
    """The profile of `case` at its worst step (module docstring), None for a balanced case
    or a run without that step."""
    from opfbench.io import load_case
    from opfbench.multiphase import PhaseNetwork
    from opfbench.powerflow.multiphase import PhaseFlowResult
    from opfbench.study.task_scenarios import chunk_scenario, study_period

    net = load_case(case).network
    when = worst_step(steps, case)
    if not isinstance(net, PhaseNetwork) or when is None:
        return None
    cfg = manifest.get("config", {})
    period, _ = study_period((case,), ("off",), str(cfg.get("period")), str(cfg.get("night")), cfg.get("step_minutes"))
    row = int(period.index.get_indexer([when])[0])
    if row < 0:
        return None
    step = pd.Timedelta(hours=period.step_h)
    scenario = chunk_scenario(
        case,
        "connected",
        "off",
        period.profiles.iloc[row : row + 2],
        period.night[row : row + 2],
        1,
        step,
        str(cfg.get("forecast_dir")),
    )
    flow = scenario.flow(np.zeros((1, len(net.ders))))
    assert isinstance(flow, PhaseFlowResult)
    if not flow.converged[0]:
        return None
    vm = flow.node_vm_pu[0]
    dist, up = net.bus_distance
    node_of = {(int(b), int(p)): i for i, (b, p) in enumerate(zip(net.node_bus.tolist(), net.node_phase.tolist(), strict=True))}
    segments: dict[int, tuple[list, list]] = {p: ([], []) for p in PHASES}
    for bus in range(net.n_bus):
        parent = int(up[bus])
        if parent < 0 or not np.isfinite(dist[bus]):
            continue
        for p in PHASES:
            here, there = node_of.get((bus, p)), node_of.get((parent, p))
            if here is not None and there is not None:
                xs, ys = segments[p]
                xs += [float(dist[parent]), float(dist[bus]), None]
                ys += [float(vm[there]), float(vm[here]), None]
    phase_vm = vm[np.isin(net.node_phase, PHASES)]
    return Profile(case, when, segments, net.band, float(phase_vm.min()), float(phase_vm.max()))
