"""Fabrication: printability facts, contour extraction, one-piece connectivity, the minimum open channel
width, and the incremental-compliance term with its elasticity solver, multigrid and deflation (section 3.6,
5.2)."""
