"""Fleet archives: reprocess a tree of recordings on Dask into a Parquet dataset (one row per
recording), and follow each robot's calibration over time (`robocal fleet`)."""
