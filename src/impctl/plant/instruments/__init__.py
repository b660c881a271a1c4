"""What the controller and the gateway see: room and outdoor sensors, the heat meter
(:mod:`.sensors`)."""
