"""The owner recorder: the house recorded read-only between IMP nights (:mod:`.recorder`), a
record's rows (:mod:`.rows`) and its labels (:mod:`.labels`)."""
