"""Scoring path predictions the paper's way: pooled pixel counts, baselines, the results table, figures."""
