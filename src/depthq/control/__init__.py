"""Controllers below `depthq.data` (collection drives them): the Policy interface, OU exploration, the
depth heuristic, action selection and the greedy base of the learned policies (`depthq.policies`)."""
