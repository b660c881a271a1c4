"""What the controller and the gateway see: room and outdoor sensors, the heat meter
(:mod:`.sensors`); the heat pump's flow and return sensors over a season (:mod:`.water`)."""
