"""One process drives the heat pump: the store's lock (:mod:`.store`) and the heat pump's
(:mod:`.heat_pump`)."""
