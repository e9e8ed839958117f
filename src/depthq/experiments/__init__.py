"""Experiments: measurements behind the docs, as code of the project (each a module with `run` and
`table`, runnable as `python -m depthq.experiments.<name>`, tested at toy size). They sit above
`depthq.report`, whose sweeps and probes they drive."""
