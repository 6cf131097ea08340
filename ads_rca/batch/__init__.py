"""Batch diagnosis of many runs (``ads-rca batch``): the pure core.

What runs where: :mod:`~ads_rca.batch.inputs` expands the command line into runs (each with
a stable run id), :mod:`~ads_rca.batch.work` diagnoses one run in a child process with a
timeout (the function a Dask task calls), :mod:`~ads_rca.batch.rows` turns a verdict into one
flat row, :mod:`~ads_rca.batch.store` writes the rows incrementally (CSV, Parquet, per-run
JSON) and reads them back for ``--resume``, :mod:`~ads_rca.batch.summary` prints the counts
and writes the HTML summary. No module here imports Dask: the command shell
(:mod:`ads_rca.commands.batch_cmd`) owns the client and the cluster.
"""
