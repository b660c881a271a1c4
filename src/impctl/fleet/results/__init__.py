"""The FLEET output: its on-disk format and its reading back.

* :mod:`.table`: FLEET.parquet's schema, its part files, :func:`~.table.read_fleet`
* :mod:`.manifest`: the dataset's manifest — the households expected and done
* :mod:`.previous`: the last run's FLEET dataset as the start of the next
* :mod:`.flex_rows`: ``impctl flex`` on FLEET rows
* :mod:`.lock`: one run at a time in a FLEET dataset

Nothing is imported here (pyarrow, pandas and torch load with the module that needs them);
:mod:`impctl.fleet` re-exports the public names lazily.
"""
