"""The print material's constants (AquaSys 120 printed on a Prusa i3 MK3s, section 4.1)."""

PRINT_DENSITY_G_PER_CM3 = 1.32
"""Average density of the paper's prints (section 4.1)."""
