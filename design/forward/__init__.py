"""The forward model: fast marching with its exact adjoint, the release curve, the concentration
remapping, and one-call simulation of a mesh or density file (paper sections 3.2-3.5, Appendix B)."""
