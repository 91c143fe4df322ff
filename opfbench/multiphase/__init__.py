"""The node-level (multiphase) network model of unbalanced feeders: every bus with its own
phases, every element as OpenDSS compiled it.

- `model`: `PhaseNetwork` — nodes (`bus.phase`), power-delivery elements with their
  primitive admittances, lines' phase impedance and shunt matrices, transformers'
  windings and taps, the source (an EMF behind its Thevenin admittance), loads and DER
  as branches between nodes, the voltage band and the voltages it applies to.
- `branches`: loads and DER as branches between two nodes (wye phase → neutral or ground,
  delta phase pairs, split-phase halves) and OpenDSS's load models as one vectorised
  current function.

The OpenDSS reader is `opfbench.io.opendss`; the batched power flow
`opfbench.powerflow.multiphase`.
"""

from opfbench.multiphase.branches import GROUND, Branches, LoadModels
from opfbench.multiphase.model import Element, Line, PhaseNetwork, Source, Transformer, Winding

__all__ = ["GROUND", "Branches", "Element", "Line", "LoadModels", "PhaseNetwork", "Source", "Transformer", "Winding"]
