"""Paper studies: one package per paper, each with its findings and figures.

* :mod:`.biber_duckett` — Biber & Duckett 2009 §5: findings checked on an experiment's
  results, the exhibition in the timescales (Fig. 9), map structure (§5.2), timescale usage
  (Figs. 12-13) and the toy example (§3.5, Fig. 2).
* :mod:`.hentschel_wagner` — Hentschel & Wagner 2011 §7: the long-term maps (Figs. 5, 8),
  point-class shares per day against the seen-before truth (Fig. 6), the error per day
  against static MCL (Fig. 7) and §7.3's findings.

A study reads the results store; the engine never imports it.
"""
