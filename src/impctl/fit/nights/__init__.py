"""The fit's input: measured nights → the rows the fit compares (:mod:`.data`), fine rows
coarsened into blocks (:mod:`.resample`), and each night's quality and the fit's adequacy
(:mod:`.quality`). numpy only, no torch."""
