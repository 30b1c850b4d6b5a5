"""Agent localization."""
