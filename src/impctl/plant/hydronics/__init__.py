"""The heating water: the emitter — radiators or underfloor, its output and capacity
(:mod:`.emitter`) — and the air-source heat pump with its control (:mod:`.heatpump`)."""
