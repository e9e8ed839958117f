"""Experiments: measurements behind the docs, as code of the project (each a module with `run` and
`table`, runnable as `python -m depthq.experiments.<name>`, tested at toy size), and the calibration
probe behind `depthq probe`. They sit above `depthq.pipeline` and `depthq.report`, whose sweeps they
run, and below the verbs."""
