"""Voltage regulators as OpenDSS's RegControl moves them (`?taps=control`): the control's
settings, the regulated transformer's admittance at every tap position, and one control
step — the sample and the tap move of OpenDSS's *static* control mode — on S snapshots.

A `Regulator` is one RegControl (its transformer `elements[element]`). Its step, as
OpenDSS's `RegControl.Sample` and `DoPendingAction` (CTRLSTATIC):

- the control voltage: the monitored winding's (`winding`) voltage on phase `pt_phase`
  (or the phase of the highest / lowest winding voltage) divided by `pt_ratio`, plus the
  line-drop compensation (R + jX)·I/`ct_rating` with I the current into that terminal
  on that phase (V);
- out of band, |V_reg − |V_control|| > band/2, it asks for round(boost/increment) taps,
  boost = (V_reg − |V_control|)·pt_ratio / the winding's base voltage (the other way when
  the tap is on another winding) and is *armed* when a tap in that direction is left;
  back in band it disarms;
- the armed regulators with the shortest time delay (`delay`, s) move — OpenDSS's static
  mode executes the nearest actions of its control queue and leaves the time where it is,
  so delays order the moves but delay nothing — each by 70 % of its asked change (at least
  one tap, at most `tap_limit`), within its range.

The power flow repeats solve and step until no regulator is armed
(`opfbench.powerflow.multiphase`); positions are indices into `taps` (`yprims` the
transformer's primitive admittance at each), starting from `start` (the tap the file
compiles to: OpenDSS's snapshot starts there too). Reverse and cogeneration modes, a
remote regulated bus, a voltage limit and Beckwith's LDC_Z are not emulated: the reader
refuses a RegControl that uses them with taps=control."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from opfbench.multiphase.branches import GROUND

PT_MAX, PT_MIN = -1, -2
"""`Regulator.pt_phase` for OpenDSS's `ptphase=max` / `ptphase=min`."""


def _frozen(arr: object, dtype: type) -> np.ndarray:
    out: np.ndarray = np.array(arr, dtype=dtype)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class Regulator:
    """One RegControl (module docstring). `element` its transformer's index in
    `PhaseNetwork.elements`; `winding` the monitored winding (terminal, 1-based),
    `tap_winding` the one whose tap moves; `vreg`, `band` (V on the PT's secondary),
    `pt_ratio`, `ct_rating` (A), `r`, `x` (V of compensation at the CT rating), `pt_phase`
    (1-based, or PT_MAX / PT_MIN), `delta` the monitored winding is delta-connected,
    `delay` (s), `tap_limit` (taps per move); `base_v` the
    monitored winding's base voltage (V); `taps` (n_pos,) p.u. tap of each position (the
    range min..max in steps of the increment through the compiled tap), `yprims`
    (n_pos, size, size) the transformer's primitive admittance there, `start` the
    position the file compiles to, `settled` the one OpenDSS settled the snapshot at."""

    name: str
    element: int
    winding: int
    tap_winding: int
    vreg: float
    band: float
    pt_ratio: float
    ct_rating: float
    r: float
    x: float
    pt_phase: int
    delta: bool
    delay: float
    tap_limit: int
    base_v: float
    taps: np.ndarray
    yprims: np.ndarray
    start: int
    settled: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "taps", _frozen(self.taps, float))
        object.__setattr__(self, "yprims", _frozen(self.yprims, complex))

    @property
    def increment(self) -> float:
        """p.u. tap per step."""
        return float(np.max(np.abs(np.diff(self.taps)))) if len(self.taps) > 1 else 0.0


@dataclass
class ControlState:
    """The control state of S snapshots (arrays (S, n_reg)): positions, armed, and the
    pending change (p.u. tap) of each regulator."""

    position: np.ndarray
    armed: np.ndarray
    pending: np.ndarray

    @classmethod
    def start(cls, regulators: tuple[Regulator, ...], n_snap: int) -> "ControlState":
        position = np.tile(np.array([r.start for r in regulators], dtype=int), (n_snap, 1))
        return cls(position, np.zeros(position.shape, dtype=bool), np.zeros(position.shape))


def control_voltage(reg: Regulator, nodes: np.ndarray, v: np.ndarray, yprim: np.ndarray) -> np.ndarray:
    """(S,) |V_control| (V, on the PT's secondary) of `reg` at node voltages v (S, n_node)
    complex, its transformer's terminal nodes `nodes` (terminals, conductors) and
    primitive admittances `yprim` (S, size, size) at each snapshot's position."""
    n_s = v.shape[0]
    vx = np.concatenate([v, np.zeros((n_s, 1), dtype=complex)], axis=1)  # GROUND → the zero column
    flat = np.where(nodes.ravel() == GROUND, v.shape[1], nodes.ravel())
    v_el = vx[:, flat]  # (S, size) conductor voltages in the element's order
    n_c = nodes.shape[1]
    phases = n_c - 1  # a transformer terminal: its phases and one more conductor
    off = (reg.winding - 1) * n_c
    # OpenDSS's winding voltages: wye (and any one-phase winding) phase − the terminal's last
    # conductor; a delta winding of three phases phase i − phase i+1
    nxt = np.roll(np.arange(phases), -1) if reg.delta and phases >= 3 else np.full(phases, phases)
    winding_v = v_el[:, off : off + phases] - v_el[:, off + nxt]
    if reg.pt_phase in (PT_MAX, PT_MIN):
        mags = np.abs(winding_v)
        phase = mags.argmax(axis=1) if reg.pt_phase == PT_MAX else mags.argmin(axis=1)
    else:
        phase = np.full(n_s, reg.pt_phase - 1 if reg.pt_phase <= phases else 0)
    rows = np.arange(n_s)
    vc = winding_v[rows, phase] / reg.pt_ratio
    if reg.r or reg.x:
        current = np.einsum("sij,sj->si", yprim, v_el)[rows, off + phase]  # into the terminal
        vc = vc + (reg.r + 1j * reg.x) * current / reg.ct_rating
    return np.abs(vc)


def sample(reg: Regulator, i: int, state: ControlState, v_control: np.ndarray) -> None:
    """OpenDSS's `Sample` of regulator `i` (`reg`) on every snapshot: pending change and
    armed flag from the control voltage v_control (S,) (module docstring)."""
    inc = reg.increment
    out = np.abs(reg.vreg - v_control) > reg.band / 2.0
    boost = (reg.vreg - v_control) * reg.pt_ratio / reg.base_v
    pending = np.where(out, np.rint(boost / inc) * inc if inc > 0 else 0.0, 0.0)
    if reg.tap_winding != reg.winding:
        pending = -pending
    pos = state.position[:, i]
    room = np.where(pending > 0, pos < len(reg.taps) - 1, pos > 0)
    state.pending[:, i] = pending
    state.armed[:, i] = np.where(out, state.armed[:, i] | ((pending != 0.0) & room), False)


def act(regulators: tuple[Regulator, ...], state: ControlState) -> np.ndarray:
    """OpenDSS's static-mode `DoNearestActions`: in every snapshot the armed regulators
    with the shortest delay move (70 % of the pending change, at least one tap, at most
    their limit, within range) and disarm. Returns (S,) bool: the snapshot had an armed
    regulator (its control loop goes on)."""
    delays = np.array([r.delay for r in regulators])
    timed = np.where(state.armed, delays[None, :], np.inf)
    nearest = timed.min(axis=1, initial=np.inf)
    moving = state.armed & (timed == nearest[:, None])
    for i, reg in enumerate(regulators):
        rows = np.flatnonzero(moving[:, i])
        if not rows.size:
            continue
        inc = reg.increment
        change = state.pending[rows, i]
        steps = np.clip(np.trunc(0.7 * np.abs(change) / inc), 1, reg.tap_limit).astype(int)
        steps = np.where(change == 0.0, 0, np.where(change > 0, steps, -steps))
        state.position[rows, i] = np.clip(state.position[rows, i] + steps, 0, len(reg.taps) - 1)
        state.armed[rows, i] = False
        state.pending[rows, i] = 0.0
    return np.isfinite(nearest)
