"""The fit's 95 % intervals: statistical and type-B parts (:mod:`.uncertainty`) and the
model-error share calibrated on realistic virtual houses (:mod:`.model_error`)."""
