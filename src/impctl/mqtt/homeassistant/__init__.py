"""What Home Assistant sees: the device and its entities (:mod:`.discovery`) and the
live state and fit results published to them (:mod:`.payloads`)."""
