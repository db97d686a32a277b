"""The Monte Carlo baseline (section 5.1): kinetic voxel erosion and its tuning against measured
curves."""
