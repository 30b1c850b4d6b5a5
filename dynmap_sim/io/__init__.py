"""Readers for recorded robot data (CARMEN logs)."""
