"""Labelled fault data sets: generation with the hybrid simulator and npz storage.

A data set is a batch of simulated flights on the 20 Hz grid. Each flight keeps
its canonical signals (``monitor.features.SIGNALS``), every propeller's
condition (0 normal, 1 bent, 2 cracked) and the paper's label derived from it,
so that any feature list can be computed later by ``monitor.features``.
"""

from offline.dataset.records import CONDITION_NAMES, FaultDataset, load_dataset, save_dataset

__all__ = ["CONDITION_NAMES", "FaultDataset", "load_dataset", "save_dataset"]
