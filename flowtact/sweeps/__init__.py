"""Sweeps: one graph over parameter grids and recordings, one table row per run (``flowtact sweep``,
``flowtact.sweep(...)``). Needs the ``sweep`` extra (pandas, pyarrow); Dask the ``dask`` extra."""
