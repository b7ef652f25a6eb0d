"""What may call a plan safe: the independent replay, flyability, and the verdict a crew reads."""
