"""The night dynamics of the fit: the 5R1C night ODE (:mod:`.node`) and its integration
(:mod:`.solver`). torch; no optimiser, no intervals."""
