"""Pedestrians steered by the social force model (Helbing & Molnár 1995, Phys. Rev. E 51).

Each person ``i`` (unit mass) is driven toward a goal and repelled by the others, by static
geometry and by the robot:

* driving term ``(v0_i e_i - v_i) / tau``  (H&M eq. 2, relaxation time ``tau``);
* person-person ``A exp((r_i + r_j - d_ij) / B) n_ij``  (H&M eq. 3-4, in the circular form
  of Helbing, Farkas & Vicsek 2000);
* obstacle ``A_w exp((r_i - d_iW) / B_w) n_iW`` from the closest point of every segment
  within reach (H&M eq. 5);
* robot: the same exponential from a disc of the robot's radius plus a comfort margin, and
  a sideways evasion term when the robot is ahead (people step aside early, to the right
  when it is dead ahead), which keeps head-on corridor meetings from ending in a stand-off.

The speed is capped at ``1.3 v0_i`` (H&M eq. 8). After the explicit Euler step a position
correction keeps bodies out of walls and furniture and at least ``ROBOT_GAP_M`` away from
the robot's body, so the simulation never shows a person inside a wall whatever the forces.
A person who reaches a goal, gets no closer to it by ``PROGRESS_M`` for ``STUCK_S``, or finds
the robot standing on it picks a new one in line of sight,
or, for a population with a ``route``, heads for the route's next waypoint (closed loop).
People are seen by the laser as two legs whose fore-aft offset follows the gait phase.
The same seed gives the same trajectories.

The pieces, composed by :class:`SocialForce` (the facade the world uses):

* :mod:`~dynmap_sim.world.people.params`: the model's parameters (``TAU_S``, ...);
* :mod:`~dynmap_sim.world.people.crowd`: :class:`Crowd`, the live state, and
  :func:`profile_fraction`, how many are present;
* :mod:`~dynmap_sim.world.people.broad_phase`: :class:`SegmentGrid`, the segments near a
  point from a uniform grid;
* :mod:`~dynmap_sim.world.people.obstacles`: :class:`Obstacles`, free space, inside tests and
  line of sight among the static segments;
* :mod:`~dynmap_sim.world.people.spawning`: placing people, choosing and renewing goals;
* :mod:`~dynmap_sim.world.people.dynamics`: the forces of one step and goal progress;
* :mod:`~dynmap_sim.world.people.correction`: the position correction after the move;
* :mod:`~dynmap_sim.world.people.legs`: the legs the laser sees, and people's poses.
"""

from dynmap_sim.world.people.broad_phase import SegmentGrid
from dynmap_sim.world.people.crowd import Crowd, profile_fraction
from dynmap_sim.world.people.dynamics import StepConstants
from dynmap_sim.world.people.obstacles import Obstacles
from dynmap_sim.world.people.params import ROBOT_GAP_M
from dynmap_sim.world.people.social_force import SocialForce

__all__ = [
    "ROBOT_GAP_M",
    "Crowd",
    "Obstacles",
    "SegmentGrid",
    "SocialForce",
    "StepConstants",
    "profile_fraction",
]
