"""The learned policies, above `depthq.blocks`: a checkpoint's Q-net on torch (`qnet`), an exported graph
on onnxruntime (`onnx`); `spec.PolicySpec` names any policy, `registry.make_policy` builds it."""
