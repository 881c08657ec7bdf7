"""The batch script's machinery (``aasdf_batch.py``): options, job files, running jobs in this process, in worker
processes or on a Dask cluster, and the report. Nothing here is imported by the add-on itself."""
