"""The fit's optimiser: the least-squares problems, their rows and residuals (:mod:`.problem`),
Levenberg–Marquardt over merged starts and nights (:mod:`.lm`), and many households in one call
(:mod:`.batch`, the fleet)."""
