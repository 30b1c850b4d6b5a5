"""Control (agent role): velocity commands that follow a path.

* :mod:`.controller` — the Controller role and its registry;
* :mod:`.pure_pursuit` — ``pure-pursuit``: regulated pure pursuit (Coulter 1992).
"""
