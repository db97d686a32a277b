"""The forward model: fast marching with its exact adjoint, the release curve and the concentration
remapping (paper sections 3.2-3.5, Appendix B)."""
