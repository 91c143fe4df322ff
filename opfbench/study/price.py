"""The default energy price of the report's money rows (light: no heavy imports, so the
CLI can show it in `opfbench run --help`)."""

DEFAULT_PRICE_PER_KWH = 0.20
DEFAULT_CURRENCY = "EUR"
DEFAULT_PRICE_SOURCE = (
    "Eurostat, EU average electricity price for non-household consumers, second half of 2023, "
    "excluding VAT and recoverable taxes (≈ 0.20 EUR/kWh; dataset nrg_pc_205, "
    "Statistics Explained 'Electricity price statistics', April 2024)"
)
"""The price a DSO-sized buyer pays for the energy it loses."""
