"""RMS (phasor) fault ride-through simulation of a feeder (paper §IV): the
network behind an upstream Thevenin source, static loads, third-order induction motors,
current-controlled inverters with the Danish LVRT reactive current; recovery times per
bus × strategy × k × forecast.

Modules: params (model parameters, variants), motor (motor steady state), model (the
dynamic model started from the AC power flow), kernel (numba inner loop, RK4),
simulate (one fault run and its measures), point (the operating point and upstream
source), study (the study grid as a task family of `opfbench.study.engine`, its tables
and files), recovery (recovery per simulation and against no action).
"""
