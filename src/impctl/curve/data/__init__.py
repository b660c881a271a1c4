"""What the heating curve is worked out from: the NIGHTS rows with the water temperatures
(:mod:`.rows`), their steady blocks (:mod:`.blocks`), and rows simulated on the realistic plant
for the tests, the bench and the examples (:mod:`.synth`)."""
