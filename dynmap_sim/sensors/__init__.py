"""Simulated sensors: laser scanners and wheel odometry (DESIGN.md §4)."""
