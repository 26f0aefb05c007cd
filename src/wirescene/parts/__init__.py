"""Part detectors: descriptors (:mod:`.features`), random forest and response maps (:mod:`.detector`)."""

#: Largest smoothing of a part model's response maps (sigma in box heights; the shipped model's is
#: 1/16): one box height already spreads every part over the whole box. Here, free of imports, for
#: the command line's options.
MAX_SMOOTH = 1.0
