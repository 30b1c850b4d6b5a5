"""The time-specific maps of ``fremen`` and ``markov-grid`` against the truth of each run."""
