"""The building: the 5R1C envelope with its capacity split and time step (:mod:`.envelope`), and
the heat that enters it besides the heating — internal and solar gains (:mod:`.gains`)."""
