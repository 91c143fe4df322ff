"""Embedded public time series and the profiles built from them."""
