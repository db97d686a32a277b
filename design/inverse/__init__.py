"""Inverse design (paper sections 3.3-3.4): problem set-up, design spaces, targets, filters, the
objective, the optimisers, the optimisation loop and the multi-start; no file I/O (a run's folder is
`design.files.rundir`)."""
