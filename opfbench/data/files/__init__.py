"""Derived data files embedded in opfbench (see PROVENANCE.md and manifest.json here).

Regenerate with ``python -m opfbench.data.derive --source <raw data folder>``."""
