"""Commands for the analyst: simulate, train, classify, fit, fleet, flex, campaign, demo, report.
Heavy libraries (torch, scikit-learn, pandas, Dask) are imported inside each command."""
