"""Hentschel & Wagner 2011's adaptive memory model as a localizer (``adaptive-memory``).

One module per method of the paper: :mod:`.memory_stores` (§3, eq. 1: SM/STM/LTM circular
buffers), :mod:`.object_tracker` (§4.2, eqs. 8-11: boxes, Kalman tracking, speed classes),
:mod:`.ltm_map` (§4.3, eqs. 12-15: long-term occupancy grids; §4.4: the semistatic test) and
:mod:`.localizer` (§6.1: MCL on the static points and the best-fitting long-term map).
"""
