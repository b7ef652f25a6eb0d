"""Does it still land when the model is wrong: the closed loop, robust verification, robust envelopes."""
