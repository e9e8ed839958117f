"""Live experiments: how a published table of docs/ is made now (each a module with `run` and `table`,
runnable as `python -m depthq.experiments.<name>`, tested at toy size), each pinning the full configs it
trains with, so its documented command reproduces its documented numbers on a later commit. Finished
investigations are research/'s, outside the package. They sit above `depthq.pipeline` and
`depthq.report`, whose sweeps they run, and below the verbs (which never import them)."""
