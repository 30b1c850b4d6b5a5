"""Control (agent role): velocity commands that follow a path.

* :mod:`.controller` — the Controller role and its registry;
* :mod:`.pure_pursuit` — ``pure-pursuit``: regulated pure pursuit (Coulter 1992);
* :mod:`.corridor_follower` — ``corridor-follower``: H&W 2011 §6.3's hybrid controller
  (pure-pursuit tracking, reactive avoidance by a lateral offset inside the route corridor,
  clearance speed law, ``blocked`` for global replanning);
* :mod:`.collision_monitor` — a safety stop between any controller and the robot (nav2's
  Collision Monitor: stop / slowdown zones from the raw scan in the robot frame);
* :mod:`.recovery` — stuck detection and recovery (nav2's progress checker and behaviour-tree
  recovery: wait, back up, replan, give up).
"""
