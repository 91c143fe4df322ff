"""The strategy registry, split by duty (import the module you need; this package imports
nothing, so its low modules load without the catalog):

- `options`: typed options — what a label's `key=value` may say, parsed, checked, written back.
- `specs`: the tables of strategies and formulation models, and how entries join them (the
  decorators of the modules that define them register there: `strategies.registration`,
  `formulations.model`, `specs.strategy`).
- `references`: the configurations the benchmark names — the baseline, the reference
  optimum, the paper's rules, the default grids (names only, light to import).
- `catalog`: lookup by name (built-ins loaded on first need, then the entry-point plugins),
  configuration labels, which label is a formulation or a relaxation.

Loading plugins (files, modules, entry points) is `opfbench.plugins`'s.
"""
