"""What the flight tells of the model: today's gross weight and the disturbance accelerations."""
