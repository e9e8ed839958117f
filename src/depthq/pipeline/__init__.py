"""The reproduction pipeline: a sweep's grid (networks × sizes × seeds × settings), its presets, the
names of a run folder, and its resumable stages (collect → features → train → evaluate)."""
