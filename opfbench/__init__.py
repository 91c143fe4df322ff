"""opfbench: communication-free local reactive-power rules vs centralized OPF.

Units everywhere unless stated: MW, MVAr, kW for losses, p.u. voltages on the case's
MVA base. Sign convention: P and Q positive = injected into the grid (generation);
loads are positive consumption.
"""

__version__ = "0.1.0"
