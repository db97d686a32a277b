"""Records on disk: what ``run.json`` says (:mod:`~labapp.records.runrecord`: the typed record, its format and
migration), crash-safe files (:mod:`~labapp.records.fileio`), run folders written (:mod:`~labapp.records.storage`),
read (:mod:`~labapp.records.manifests`) and verified (:mod:`~labapp.records.verification`), output-path checks
(:mod:`~labapp.records.outpaths`), and the one reader of physical release curves
(:mod:`~labapp.records.curvefiles`)."""
