"""Experiments as sweeps of trials: a trial is a pure function of (configuration, seed) that
returns a result row; a sweep runs a manifest of trials on an executor (serial, a local
process pool, a Dask cluster), appends the rows to a JSON-lines file and resumes after a kill.

Modules: `trial` (the trial record, its content key, the experiments' registry), `store`
(manifest and rows on disk), `executors` (where trials run), `runner` (the sweep itself),
`provenance` (what ran a trial: git revision, package versions, host). Nothing here imports
numpy at module level, so a pool worker can limit its BLAS threads before numpy loads.
"""
