"""Geometry: sample shapes and exact voxelisation of closed meshes."""
