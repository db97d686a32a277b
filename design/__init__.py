"""The embedded simulator and optimizer (paper sections 3.1-3.6)."""
