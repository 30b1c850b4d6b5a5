"""The simulated world: world files, calendar and schedule, people (DESIGN.md §2-3)."""
