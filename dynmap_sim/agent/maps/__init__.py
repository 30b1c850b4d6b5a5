"""Agent maps."""
