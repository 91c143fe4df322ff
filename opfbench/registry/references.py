"""The configurations the benchmark names: the references every comparison is made
against, the paper's own configurations and the default grids. Names only (light to
import: the CLI's help texts read them); `catalog` resolves them.
"""

#: The reference configurations every comparison is made against: the baseline (every DER
#: at Q = 0) and the optimum whose loss reduction the others' shares are measured by.
BASELINE = "no-action"
REFERENCE_OPTIMUM = "acopf"
#: The paper's own configurations, which its claims are about (`report.claims`): its local
#: rules (LLMA, LFMA) and its OPF setup.
PAPER_RULES = ("llma", "lfma")
PAPER_OPF = "acopf-paper"
#: `opfbench run`'s default grid, declared: the paper's configurations, the grid codes'
#: rules and the OPF problem's exact model and relaxation, each at its default options
#: (a new strategy joins it only by being named here; the learned ones have no default
#: configuration: their parameters come from a training period or a file).
DEFAULT_RUN = (
    BASELINE,
    *PAPER_RULES,
    "volt-var",
    "watt-var",
    "volt-watt",
    "volt-var+volt-watt",
    "const-pf",
    "cosphi-p",
    "q-u",
    REFERENCE_OPTIMUM,
    PAPER_OPF,
    "socp",
)
#: The default grid's strategies under a forecast source: the paper's Algorithm 3 rules
#: (the grid codes' rules know no forecast; only Algorithm 3's limit would change them).
DEFAULT_FORECAST = PAPER_RULES
#: `opfbench fault`'s default strategies: the baseline, the paper's rules, the grid code's
#: Volt-VAR and the optimum.
DEFAULT_FAULT = (BASELINE, "llma", "lfma", "volt-var", REFERENCE_OPTIMUM)
