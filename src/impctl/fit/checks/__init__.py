"""What a fit checks of itself before it reports: which problem is reported, by likelihood
ratio (:mod:`.selection`); what it must not report as determined (:mod:`.undetermined`); its
in-sample validation (:mod:`.validation`); and what it can say of its instruments
(:mod:`.cross_checks`, :mod:`.instruments`)."""
