"""Planning (agent role): paths on the agent's own obstacle grid (A*)."""
