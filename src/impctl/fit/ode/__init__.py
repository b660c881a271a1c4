"""The night dynamics of the fit: the 5R1C night ODE (:mod:`.node`) and its integration
(:mod:`.solver`), its parameters — bounds, transforms, what a row means for the house
(:mod:`.parameters`) — and its input, the nights packed side by side (:mod:`.packing`). torch; no
optimiser, no intervals."""
