"""Running the plant: many houses in one loop over time steps (:mod:`.simulate`), one house
step by step for the simulator (:mod:`.stepper`)."""
