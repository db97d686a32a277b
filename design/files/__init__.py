"""Design's only file I/O: reading meshes and density arrays, and writing a design run's folder
(outputs, checkpoints, report picture)."""
