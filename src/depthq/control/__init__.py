"""Controllers: everything that maps an observation to an action (exploration, expert, Q-net policies)."""
