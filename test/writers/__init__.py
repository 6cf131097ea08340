"""Writers of dataset files shaped like the released ones (tables, scenes, segments, run
folders, predictor files), for tests and benches: not part of the installed package."""
