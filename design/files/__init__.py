"""Design's only file I/O: reading meshes, density arrays and target curves, one-call simulation of a mesh or
an input file, and a design run's folder (`rundir.run_design`: configuration, checkpoints, outputs, report
picture). The other sub-packages of design never import it."""
