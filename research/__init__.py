"""The experiments behind docs/, outside the installed package (pyproject finds packages under src/
only; no `depthq` module imports one). Live ones say how a published table is made now (`looks`,
`camera_labels`, `sizing`, `weights_check`, `ros_fidelity`: each with `run` and `table` or `report`,
pinning the full configs it trains with, so its documented command reproduces its documented numbers
on a later commit); finished ones hold the measurements behind a default or a sentence of the docs.
Run from a checkout's root as `python -m research.NAME`, tested at toy size like the package. Each
module's docstring gives its command and the commit its documented numbers came from."""
