"""Off-policy training of Depth-Q-Net and Coll-Q-Net from one collected dataset (docs/design.md#training).

Modules, one concept each: `config` (every hyper-parameter, `TrainConfig`), `features` (the
on-disk cache of frozen-trunk features), `samples` (training batches from cached features or from
images), `folder` (writing the output folder: weights, resume state, metrics; reading a network
back is `depthq.networks.load_qnet`), `trainer`
(the loop, `train`). Their speed is measured by `depthq.bench.train` and `depthq.bench.features`.
"""
