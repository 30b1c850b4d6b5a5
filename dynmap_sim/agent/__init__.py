"""The robot's own brain: maps, localization, planning and control.

Everything here sees only what a real robot sees (:mod:`dynmap_sim.types`): laser scans,
odometry, the sensor description and the prior a scenario grants. It never imports the
simulator (``world/``, ``sensors/``, ``robot/``, ``env``); an import-linter contract in
``pyproject.toml`` enforces that.
"""
