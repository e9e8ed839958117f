"""Reproduction of the paper's results: the pipeline, its tables, figures and HTML report."""
