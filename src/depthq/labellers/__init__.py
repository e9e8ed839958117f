"""The camera labellers: learned models, besides the Q-nets, that estimate each frame's depth bins from
the camera (and odometry), so a Depth-Q-Net can learn without a LiDAR: labeller.py (a labeller's
folder, its training and the labelling of a dataset: `depthq labeller`, `depthq label`), floor.py (free
floor learnt from the robot's footprint), monodepth.py (self-supervised depth from consecutive frames);
the perception labeller (another family's LiDAR) is labeller.py's. The labels they write into a run
file are `depthq.data.camera_labels` (docs/formats.md)."""
