"""Agent mapping."""
