"""The learned policies, above `depthq.nets`: a checkpoint's Q-net on torch (`qnet`), an exported graph
on onnxruntime (`onnx`), and `registry.make_policy`, which builds any policy from its `spec`."""
