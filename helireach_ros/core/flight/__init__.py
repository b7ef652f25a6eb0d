"""A simulated helicopter: the model with a mismatch and sensor noise, the uncertainty set, named presets."""
