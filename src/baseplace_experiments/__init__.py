"""The papers' experiments, outside the core library.

Each module reproduces one experiment of the seed papers on generated scenes with exact ground
truth (:mod:`baseplace.sim`): segmentation accuracy, navigation, Tables I/II of the oriented
surface reachability maps, the surface map's agreement with IK, the inspect-table task and the
radial candidates' table grid. They import the library; the library never imports them. Their
commands are registered into ``baseplace experiment ...`` by :mod:`baseplace_experiments.cli`;
results files carry their provenance (:mod:`baseplace_experiments.results`).
"""
