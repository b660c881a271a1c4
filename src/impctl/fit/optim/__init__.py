"""The fit's optimiser: Levenberg–Marquardt over merged starts and nights (:mod:`.lm`), and
many households in one call (:mod:`.batch`, the fleet)."""
