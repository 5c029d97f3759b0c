"""Training: the train state, G run with given parameters, the objectives, the jitted step, the loop,
checkpoints, data-parallel training and the shipped model."""
