"""Fabrication: printability facts, contour extraction, one-piece connectivity, and the
incremental-compliance term with its elasticity solver, multigrid and deflation (section 3.6, 5.2)."""
