"""Timing benchmarks and the scripts that draw the docs' figures, run from a checkout as ``python -m benchmarks.NAME``.

Shared by them and by ``studies``: `benchmarks.untuned_shapes` and `benchmarks.robust_sources` (source meshes none
of the defaults were tuned on), `benchmarks.designs` (a design of such a source judged by its print) and
`benchmarks.analytic` (solids with closed-form releases). What each script measures: docs/benchmarks.md.
"""
