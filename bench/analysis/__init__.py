"""Analysing results: the report and its plots, shifted geometric means and
performance profiles, the paper's claims, the regression compare."""
