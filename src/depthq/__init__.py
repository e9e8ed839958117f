"""depthq: learn monocular collision avoidance from future depth (Depth-Q-Net) or collisions (Coll-Q-Net).

Layers, each importing only from those before it; every name is a folder (a package) or, in the base
layer, a module, so the folders show the layers (tests/test_layers.py reads this list and checks the
source against it, folders and files):

    errors, configio, checksum, lock,       base: no layer below (checksum: the SHA-256 a JSON record
    parallel, flags, progress,              or file carries; lock: a folder's one writer; progress:
    host                                    bars quiet without a terminal)
    ← sim                                   canyons, MuJoCo world, sensors, the Gymnasium env
    ← control                               the Policy interface, OU exploration, the depth heuristic,
                                            action selection rules (collection drives them)
    ← data                                  collection and the on-disk datasets, ROS 2 bags
    ← blocks                                a network's building blocks: trunks, heads, losses, optimizer,
                                            the migrations of old records
    ← networks                              Depth-Q-Net, Coll-Q-Net and any network registered by name:
                                            what differs between networks, asked by every layer above
    ← checkpoint                            the checkpoint folder: its format, the folder a training writes
                                            once per epoch and resumes, which weights act
    ← policies                              the learned policies (torch or onnxruntime) and
                                            `make_policy`, which builds any policy from its spec
    ← train                                 the trainer, and the offline metric that re-runs its
                                            validation
    ← labellers                             the camera labellers: learned models that estimate depth bins
                                            from the camera (`depthq labeller`, `depthq label`)
    ← evaluate | deploy                     online evaluation and the calibration probe (`depthq probe`) |
                                            ONNX export, the robot's node core, `depthq ros`'s
                                            ROS 1 nodes and the simulated robot
    ← pipeline                              a sweep's grid, presets, run folder and resumable stages
    ← report | bench                        a sweep folder's tables, figures, findings and HTML report |
                                            `depthq bench` figures
    ← scripts ← cli, cli_reference          one module per verb, the `depthq` command, its reference
                                            page (docs/cli.md)

Names joined by `,` form one unit, whose modules may import each other; units on one line (`|`) do
not import each other. This root module runs first and imports only `depthq.sim`'s `__init__` (the
env's name); any module may import it for `__version__`.
"""

import os

# Offscreen rendering must be chosen before mujoco is imported anywhere.
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])

__version__ = "0.1.0"

# `import depthq` registers depthq/Canyon-v0 (as ale_py does for ALE/…), so that
# gymnasium.make("depthq/Canyon-v0") works after it and gymnasium.make("depthq:depthq/Canyon-v0")
# without it. Registering stores a name only: mujoco is imported when the env is made.
from depthq.sim import ENV_ID

__all__ = ["ENV_ID", "__version__"]
