"""The differential-drive robot body (DESIGN.md §4)."""
