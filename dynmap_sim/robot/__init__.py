"""The differential-drive robot body and its route progress (docs/architecture.md §4)."""

from dynmap_sim.robot.diff_drive import DiffDriveRobot, RobotParams, StepResult
from dynmap_sim.robot.route import RouteProgress

__all__ = ["DiffDriveRobot", "RobotParams", "RouteProgress", "StepResult"]
