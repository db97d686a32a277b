"""Scale-out: the Dask cluster, design sweeps and batch reanalysis, each fanning out the jobs of
`labapp.jobs`."""
