"""What each shipped case holds, counted once from its file and pinned (the reader, the CLI
and the case builders are checked against it)."""

# name: buses, branches (in service), DER units, total load MW / MVAr (case33bw: Baran & Wu's
# 3.715 MW / 2.3 MVAr; case69: MATPOWER's 3802.19 kW / 2694.60 kVAr, its rows summed at 1e-4),
# meshed; the DER cases share their base case's loads.
SHIPPED = {
    "case33bw": (33, 37, 32, 0, 3.715, 2.3, False),
    "case69": (69, 68, 68, 0, 3.8021, 2.6947, False),
    "case141": (141, 140, 140, 0, 11.944625, 7.402614, False),
    "paper33": (33, 37, 32, 5, 3.715, 2.3, False),
    "paper33-meshed": (33, 37, 37, 5, 3.715, 2.3, True),
    "case69-der": (69, 68, 68, 5, 3.8021, 2.6947, False),
    "case141-der": (141, 140, 140, 5, 11.944625, 7.402614, False),
    "feeder1k": (990, 989, 989, 150, 3.715, 2.3, False),
    "feeder10k": (9999, 9998, 9998, 1515, 3.715, 2.3, False),
}

# The shipped unbalanced feeders (OpenDSS): buses, nodes, load elements — as OpenDSS counts
# them (`Circuit.NumBuses`, `Circuit.NumNodes`, `Loads.Count`) for the shipped files — and
# the PV units of each feeder's placement rule (`opfbench.cases.opendss_pv`: every second
# load, 25 % of ckt24's 3638 single-phase loads).
UNBALANCED = {
    "ieee13": (16, 41, 15, 8),
    "ieee34": (37, 95, 68, 34),
    "ieee37": (39, 117, 30, 15),
    "ieee123": (132, 278, 91, 46),
    "eulv": (907, 2721, 55, 28),
    "ieee8500": (4876, 8531, 1177, 589),
    "ckt5": (2998, 3437, 1379, 690),
    "ckt7": (1255, 2452, 906, 453),
    "ckt24": (6058, 7522, 3891, 910),
}
