"""Networks: image trunks, the Depth-Q-Net and Coll-Q-Net heads, their losses and optimizer."""
