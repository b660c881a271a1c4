"""The heating curve on the device: the last result kept (:mod:`.state`) and the watch that
puts it on the heat pump when the owner asked for it (:mod:`.watch`)."""
