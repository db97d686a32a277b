"""Studies behind the docs' evidence pages, run from a checkout as ``python -m studies.NAME``.

Each answers one question about the design or calibration code and prints a table (some write a CSV into
``studies/results``); its docstring says what it prints and which page cites it. They share the sources and
helpers of the ``benchmarks`` package. The list: docs/benchmarks.md#studies.
"""
