"""Off-policy training of Depth-Q-Net and Coll-Q-Net from one collected dataset (docs/design.md#training).

Modules, one concept each: `config` (every hyper-parameter, `TrainConfig`), `features` (the
on-disk cache of frozen-trunk features), `samples` (training batches from cached features or from
images), `trainer` (the loop, `train`, which writes its checkpoint folder through `depthq.checkpoint`
once per epoch). Their speed is measured by `depthq.bench.train` and `depthq.bench.features`.
"""
