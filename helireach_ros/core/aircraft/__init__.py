"""The aircraft: the airframe file and its limits, the six-state model after power loss, the rotor's inflow."""
