"""The NIGHTS file: read and written (:mod:`.nights_csv`), its values checked (:mod:`.values`),
its optional columns per night (:mod:`.extras`) and per row (:mod:`.series`, :mod:`.phase`), the
held-setpoint test of unlabelled nights (:mod:`.held`), the size guard (:mod:`.limits`) and what
a file that cannot be read likely has wrong (:mod:`.hints`)."""
