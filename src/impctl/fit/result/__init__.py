"""A fit's result, read without torch: the JSON summary (:mod:`.report`), its printed table
(:mod:`.table`) and its figure (:mod:`.plot`)."""
