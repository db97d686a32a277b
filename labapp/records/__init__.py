"""Records on disk: crash-safe run folders and their verification, output-path checks, and the
one reader of physical release curves."""
