"""Running jobs: the runner, worker processes and isolation, external programs,
executors (local, Dask), timing and calibration, the results file and its columns."""
