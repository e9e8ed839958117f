"""Finished investigations: the measurements behind docs/ whose result is already a default or a
sentence there. Not part of the installed package (pyproject finds packages under src/ only); run from
a checkout's root as `python -m research.NAME`, tested at toy size like the package. Each module's
docstring gives its command and the commit its documented numbers came from."""
