"""The rendering of a sweep folder: the paper's tables, figures, the findings (claims, deviations)
and the self-contained HTML report; `reproduce` runs the pipeline and then renders it."""
