"""What the bench scripts share (not run on their own): the held-out households and their
nights as the gateway runs them (``fit_protocol``, ``campaign_nights``, ``campaign_sim``), the
printed tables (``fit_tables``, ``campaign_report``), ``fit.py --speed`` (``fit_speed``) and
``fit.py --compare`` / ``--virtual-imp`` (``fit_variants``), the groups of realism the error
budgets switch off (``realism_groups``)."""
