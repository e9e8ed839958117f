"""The same pose in every look (docs/design.md#looks): one camera frame per look, as the robot's camera
takes it (the textured looks through their camera model), side by side.

    python -m depthq.experiments.looks [OUT]   # OUT/looks.png (default docs/)
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from depthq.sim.env import CanyonEnv, EnvConfig
from depthq.sim.look import LOOKS
from depthq.sim.world import WorldConfig, world_for

CANYON = "hard/val:1000"  # a val canyon: the docs show no test canyon
POSE_STEPS = 8  # straight ahead for this many decisions, then one turning step (blur in the textured looks)


def frames(canyon: str = CANYON, looks: tuple[str, ...] = LOOKS) -> dict[str, np.ndarray]:
    """Each look's camera frame after the same drive (seed 0) into `canyon`."""
    out = {}
    for look in looks:
        family = "hard" if canyon.startswith("hard/") else "paper"
        world = replace(world_for(WorldConfig(), family), look=look)
        env = CanyonEnv(EnvConfig(world=world))
        try:
            obs, _ = env.reset(seed=0, options={"canyon": canyon})
            for action in [0.0] * POSE_STEPS + [0.8]:
                obs, *_ = env.step(np.array([action], np.float32))
            out[look] = obs["image"].copy()
        finally:
            env.close()
    return out


def figure(path: Path, canyon: str = CANYON) -> None:
    """A 2 × 2 grid of the looks' frames, each labelled, as a PNG."""
    shots = frames(canyon)
    tiles = []
    for look, image in shots.items():
        tile = Image.fromarray(image)
        ImageDraw.Draw(tile).text((8, 6), look, fill=(255, 255, 255))
        tiles.append(np.asarray(tile))
    half = (len(tiles) + 1) // 2
    grid = np.concatenate([np.concatenate(tiles[:half], 1), np.concatenate(tiles[half:], 1)], 0)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(grid).save(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m depthq.experiments.looks", description=__doc__)
    parser.add_argument("out", nargs="?", type=Path, default=Path("docs"), help="folder of looks.png")
    args = parser.parse_args(argv)
    figure(args.out / "looks.png")
    print(f"wrote {args.out / 'looks.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
