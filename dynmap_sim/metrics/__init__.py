"""Metrics: pure functions over arrays comparing estimates with ground truth (DESIGN.md §6)."""
