"""Records on disk: what ``run.json`` says (:mod:`~labapp.records.runrecord`: the typed record, its format and
migration), crash-safe run folders and their verification (:mod:`~labapp.records.storage`), output-path checks
(:mod:`~labapp.records.outpaths`), and the one reader of physical release curves
(:mod:`~labapp.records.curvefiles`)."""
