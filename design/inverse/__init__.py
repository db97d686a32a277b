"""Inverse design (paper sections 3.3-3.4): problem set-up, design spaces, targets, filters, the
objective, the optimisers and the resumable optimisation loop."""
