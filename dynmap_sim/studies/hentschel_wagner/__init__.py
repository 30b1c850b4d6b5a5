"""Hentschel & Wagner 2011 §7: the adaptive memory model's findings and figures (Figs. 5-8)."""
