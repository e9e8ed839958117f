"""Taking a trained policy out of depthq: `onnx_export` writes a Q-net as one ONNX graph that a robot
runs with onnxruntime and numpy alone (`depthq.policies.onnx` drives it)."""
