"""Networks: image trunks (EfficientNet-Lite0, MobileNet-v1-0.25), the Depth-Q and Coll-Q heads, losses, optimizer."""
