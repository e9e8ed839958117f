"""Benchmarks behind `depthq bench WHAT`, one module per figure: `sim` (env steps/s), `collect`
(collection steps/s with storage), `features` (trunk features/s end to end), `train` (head training
samples/s against matmul FLOP/s), `policy` (ms per decision, alone and in a batch), `evaluate` (an
evaluation one canyon at a time vs in lock-step). They measure speed and assert nothing:
the tests never time anything. A layer above the pipeline (it may import any of sim … evaluate).
"""
