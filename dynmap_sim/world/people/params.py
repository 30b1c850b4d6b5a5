"""Parameters of the pedestrian model [SI units]: forces, goals, legs."""

TAU_S = 0.5
A_PEOPLE = 2.1
B_PEOPLE = 0.3
A_WALL = 4.0
B_WALL = 0.12
A_ROBOT = 6.0
B_ROBOT = 0.25
ROBOT_GAP_M = 0.10
A_EVADE = 1.5
KEEP_RIGHT_M = 0.15
B_EVADE = 0.8
REACH_M = 1.0
CELL_M = 0.5
GOAL_TOL_M = 0.4
STUCK_S = 4.0
PROGRESS_M = 0.2
PAUSE_S = 2.0
LEG_RADIUS_M = 0.06
LEG_SPREAD_M = 0.10
STRIDE_M = 1.2
LEG_SWING_M = 0.12
