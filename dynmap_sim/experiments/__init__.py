"""Experiments: scenarios, the calendar loop, results, reports and regression checks."""
