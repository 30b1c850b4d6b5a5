"""Simulated sensors: laser scanners and wheel odometry (docs/architecture.md §4).

* :mod:`~dynmap_sim.sensors.raycast` — exact ray casting (a compiled kernel);
* :mod:`~dynmap_sim.sensors.lidar` — URG-04LX / LMS200 presets, noise model, truth labels;
* :mod:`~dynmap_sim.sensors.odometry` — wheel encoders with UMBmark systematic errors.
"""

from dynmap_sim.sensors.lidar import (
    NOISELESS,
    PRESETS,
    Lidar,
    LidarNoise,
    LidarReading,
    make_lidar,
)
from dynmap_sim.sensors.odometry import EncoderNoise, WheelGeometry, WheelOdometry

__all__ = [
    "NOISELESS",
    "PRESETS",
    "EncoderNoise",
    "Lidar",
    "LidarNoise",
    "LidarReading",
    "WheelGeometry",
    "WheelOdometry",
    "make_lidar",
]
