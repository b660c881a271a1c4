"""Fleet fitting."""
