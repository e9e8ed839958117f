"""Oracles: the selection rules fed with the simulator's truth, and how often a policy agrees with them
along its own runs (docs/design.md#oracles).

An `Oracle` is a perfect predictor of a network's training signal, turned into an action by that
network's rule (`Network.true_scores`, `Network.choose`):

- `depth`, lookahead K: the noise-free depth bins 1 … K frames ahead of each candidate action held
  (K = 1: Depth-Q-Net's target), scored by its selection rule (its acting settings, `Selection`: the
  farthest nearest bin; for K > 1 its steps combined by the discounted mean or the minimum);
- `coll`, lookahead K: whether holding the action bumps within K frames (Coll-Q-Net's target at
  horizon K), the lowest wins; ties go straight, as the networks' rule.

`drive_oracle` drives one in canyons: what the signal can reach at a rate, whatever the network.
`agreement` re-simulates every step of an evaluation's runs from the robot's recorded pose and asks
the oracle which action it would take there: overall, on decisive steps (where the oracle's choice
matters), and in the last seconds before each collision. Nothing here needs the policy itself, so
it works on any evaluation folder.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, fields, replace
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from depthq.control.action_selection import ACTIONS, pick_best
from depthq.errors import ConfigError
from depthq.evaluate.metrics import SUCCESS_DISTANCE
from depthq.evaluate.online import recorded_config
from depthq.flags import build_config
from depthq.networks import DepthQNet, Network, get_network, network_names
from depthq.sim.canyon import FAMILIES, Canyon, CanyonId, nearest_on_polyline
from depthq.sim.env import COLLISIONS, CanyonEnv, EnvConfig
from depthq.sim.sensors import bump, depth_bins, finish_scan
from depthq.sim.world import WorldConfig, world_for

BEFORE_COLLISION_S = 2.0  # "the last seconds before a collision"


@dataclass(frozen=True)
class Oracle:
    """A perfect predictor of the network `signal` names ("depth" or "coll") `lookahead` frames ahead,
    with the rule that picks an action from it, by that network's acting settings (`acting`, a
    `Network.Acting`; None: its defaults)."""

    signal: str = DepthQNet.name
    lookahead: int = 1
    acting: Any = None

    def __post_init__(self) -> None:
        if self.signal not in network_names():
            raise ConfigError(f"oracle signal must be one of {network_names()}, got {self.signal!r}")
        k = self.lookahead
        if isinstance(k, bool) or not isinstance(k, int) or k < 1:
            raise ConfigError(f"oracle lookahead must be an integer >= 1, got {k!r}")
        own = self.network.Acting
        if self.acting is None:
            object.__setattr__(self, "acting", own())
        elif not isinstance(self.acting, own):
            raise ConfigError(f"oracle {self.signal}: its acting settings are a {own.__name__}, got "
                              f"{self.acting!r}")

    @classmethod
    def parse(cls, text: str) -> Oracle:
        """'depth', 'depth:3', 'depth:3:farthest_nearest_bin' or 'coll:5' (lookahead 1 if not given): a
        rule, the third, is its network's acting setting `rule` (Depth-Q-Net's `Selection.rule`)."""
        signal, _, rest = text.partition(":")
        lookahead, _, rule = rest.partition(":")
        try:
            k = int(lookahead) if lookahead else 1
        except ValueError:
            raise ConfigError(f"oracle {text!r}: lookahead must be an integer, e.g. depth:3") from None
        if not rule:
            return cls(signal, k)
        acting = get_network(signal).Acting if signal in network_names() else None
        if acting is None or "rule" not in {f.name for f in fields(acting)}:
            raise ConfigError(f"oracle {text!r}: only the oracle of a network with a rule setting takes one")
        return cls(signal, k, build_config(acting, {"rule": rule}))

    @cached_property
    def network(self) -> Network:
        """The network whose signal it predicts."""
        return get_network(self.signal)

    def score(self, bins: np.ndarray, bumped: np.ndarray) -> np.ndarray:
        """Each candidate's score from its true bins (N, K, bins) and bump flags (N,)."""
        return self.network.true_scores(bins, bumped, self.acting)

    def pick(self, scores: np.ndarray) -> float:
        """The action its rule takes: the best score (depth: highest; coll: lowest), ties straight."""
        return pick_best(scores, np.array(ACTIONS), self.network.maximise, self.network.tie_tol)

    def __str__(self) -> str:
        rule = getattr(self.acting, "rule", None)
        return f"{self.signal}:{self.lookahead}{f':{rule}' if rule and self.lookahead > 1 else ''}"


class OracleWorld:
    """A noise-free copy of an evaluation's world, to try each candidate from a pose (and, with
    `camera`, to render the frame a policy saw there)."""

    def __init__(self, config: EnvConfig, camera: bool = False) -> None:
        self.env = CanyonEnv(config, camera=camera)
        self.exact = replace(config.world.lidar, noise_std=0.0)
        self.rng = np.random.default_rng(0)  # finish_scan's noise is off: unused

    def load(self, canyon: str) -> None:
        self.env.reset(seed=0, options={"canyon": canyon})

    def scores(self, oracle: Oracle, pose: np.ndarray) -> np.ndarray:
        """The oracle's score of each of ACTIONS from `pose` (depth: higher is better; coll: 0 or 1)."""
        return oracle.score(*self.truth(oracle, pose))

    def truth(self, oracle: Oracle, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """From `pose`, each of ACTIONS held `oracle.lookahead` frames: the true bins (N, K, bins) and
        whether it bumps (N,)."""
        world, config = self.env.world, self.env.config
        preds, bumped = [], []
        for action in ACTIONS:
            world.place(*pose)
            steps, hit = [], False
            for _ in range(oracle.lookahead):
                contact = world.advance(float(action))
                scan = finish_scan(world.raycast(), self.exact, self.rng)
                steps.append(depth_bins(scan, config.bins))
                hit = hit or contact or bump(scan, config.bump)
                if contact:  # the robot stops at a contact: the later steps see what it sees now
                    steps += [steps[-1]] * (oracle.lookahead - len(steps))
                    break
            preds.append(steps)
            bumped.append(hit)
        world.place(*pose)
        return np.array(preds), np.array(bumped)

    def frame(self, pose: np.ndarray, seed: int) -> np.ndarray:
        """The camera frame at `pose`, with pixel noise drawn from `seed`."""
        self.env.world.place(*pose)
        return self.env.world.image(np.random.default_rng(seed))

    def choose(self, oracle: Oracle, pose: np.ndarray) -> tuple[float, np.ndarray]:
        """The oracle's action at `pose` and its scores."""
        scores = self.scores(oracle, pose)
        return oracle.pick(scores), scores

    def close(self) -> None:
        self.env.close()


def env_config(canyons: list[str], decision_hz: float, time_limit_s: float | None = None,
               look: str | None = None) -> EnvConfig:
    """The evaluation env of `canyons` (one family) at `decision_hz`: the family's world and time limit,
    in `look` (None: the family's own)."""
    families = {CanyonId.parse(c).family for c in canyons}
    if len(families) != 1:
        raise ConfigError(f"oracle canyons must be of one family, got {sorted(families)}")
    family = families.pop()
    limit = FAMILIES[family].time_limit_s if time_limit_s is None else time_limit_s
    world = world_for(WorldConfig(decision_hz=decision_hz), family)
    return EnvConfig(world=world if look is None else replace(world, look=look), time_limit_s=limit)


def drive_oracle(oracle: Oracle, canyons: list[str], decision_hz: float) -> dict[str, Any]:
    """The oracle driven in `canyons` at `decision_hz`: progress, ends reached, collisions."""
    sim = OracleWorld(env_config(canyons, decision_hz))
    env, runs = sim.env, []
    try:
        for k, canyon in enumerate(canyons):
            _, info = env.reset(seed=k, options={"canyon": canyon})
            done = False
            while not done:
                action, _ = sim.choose(oracle, env.world.pose)
                _, _, terminated, truncated, info = env.step([action])
                done = terminated or truncated
            runs.append({"canyon": canyon, "progress": info["progress"], "distance": info["distance"],
                         "end_reason": info["end_reason"]})
    finally:
        sim.close()
    progress = np.array([r["progress"] for r in runs])
    return {
        "oracle": str(oracle),
        "decision_hz": decision_hz,
        "canyons": len(canyons),
        "progress_mean": float(progress.mean()),
        "reached_end": sum(r["end_reason"] == "end" for r in runs),
        "collisions": sum(r["end_reason"] in COLLISIONS for r in runs),
        "successes": sum(r["distance"] > SUCCESS_DISTANCE for r in runs),
        "runs": runs,
    }


def _checkpoint_policy(summary: dict[str, Any]) -> Any:
    """The evaluated checkpoint's policy with the evaluation's weights and acting settings."""
    from depthq.policies.qnet import QNetPolicy

    described, config = summary["policy"], recorded_config(summary)
    if not described.get("checkpoint"):
        raise ConfigError(f"predictions need a checkpoint's evaluation; {described.get('policy')!r} is none")
    # the evaluation's own request ('epoch:40'); without one, the weights the policy chose ('best', 'last')
    weights = config.weights or described.get("weights")
    return QNetPolicy.from_checkpoint(Path(described["checkpoint"]), weights=weights, acting=config.acting)


def _obstacle_kind(canyon: Canyon, xy: np.ndarray) -> str:
    """'pillar' when the nearest obstacle at `xy` is a pillar's surface, else 'wall'."""
    wall = min(float(nearest_on_polyline(line, xy[None])[0][0]) for line in (canyon.left, canyon.right))
    if not len(canyon.obstacles):
        return "wall"
    pillar = float((np.hypot(*(canyon.obstacles[:, :2] - xy).T) - canyon.obstacles[:, 2]).min())
    return "pillar" if pillar < wall else "wall"


def agreement(
    folder: Path, oracle: Oracle = Oracle(), predictions: bool = False
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """How often the policy of the evaluation in `folder` took the oracle's action along its own runs.

    Returns the summary (steps, agreement overall, on decisive steps, in the last BEFORE_COLLISION_S
    before each collision, and what each collision hit) and per-step arrays: canyon index, step, the
    policy's and the oracle's actions, the oracle's scores and true bins (steps, N, K, bins),
    decisive, agrees, seconds to the collision (inf where the run did not end in one). A policy's
    action agrees when the oracle scores it within the tie tolerance of its best (continuous actions
    are taken as the nearest candidate). With `predictions`, a checkpoint's policy is shown the frame
    rendered at each pose in the evaluation's look (its pixel noise drawn anew; in a look with a camera
    model, through a camera drawn anew, at rest) and its values are kept too: `predicted` (steps, N, …)
    and `predicted_scores` (steps, N) by its own rule."""
    folder = Path(folder)
    try:
        summary = json.loads((folder / "summary.json").read_text())
        with (folder / "runs.csv").open() as f:
            records = list(csv.DictReader(f))
        trajectories = np.load(folder / "trajectories.npz")
    except (OSError, ValueError) as err:
        raise ConfigError(f"{folder}: not a complete evaluation folder ({err})") from None
    hz = float(summary["config"]["decision_hz"])
    canyons = [r["canyon"] for r in records]
    policy = _checkpoint_policy(summary) if predictions else None
    sim = OracleWorld(env_config(canyons, hz, look=summary.get("look")), camera=policy is not None)
    candidates = np.array(ACTIONS)
    rows: dict[str, list] = {k: [] for k in ("canyon", "step", "policy", "oracle", "scores", "true_bins",
                                             "decisive", "agrees", "to_collision_s", "predicted",
                                             "predicted_scores")}
    hits = []
    try:
        for c, record in enumerate(records):
            key = record["canyon"].replace(":", "_").replace("/", "_")
            poses, actions = trajectories[f"{key}_poses"], trajectories[f"{key}_actions"]
            sim.load(record["canyon"])
            collided = record["end_reason"] in COLLISIONS
            if collided:
                hits.append(_obstacle_kind(sim.env.world.canyon, poses[-1, :2]))  # the canyon just loaded
            for t, action in enumerate(actions):
                pose = poses[t].astype(np.float64)
                true_bins, bumped = sim.truth(oracle, pose)
                scores = oracle.score(true_bins, bumped)
                choice = oracle.pick(scores)
                if policy is not None:
                    values = policy.values(sim.frame(pose, seed=t))
                    rows["predicted"].append(values)
                    rows["predicted_scores"].append(policy.network.scores(values, policy.acting))
                rows["true_bins"].append(true_bins)
                taken = int(np.abs(candidates - action).argmin())
                best = scores.max() if oracle.network.maximise else scores.min()
                spread = scores.max() - scores.min()
                rows["canyon"].append(c)
                rows["step"].append(t)
                rows["policy"].append(float(action))
                rows["oracle"].append(choice)
                rows["scores"].append(scores)
                rows["decisive"].append(spread > oracle.network.decisive)
                rows["agrees"].append(abs(scores[taken] - best) <= oracle.network.tie_tol)
                rows["to_collision_s"].append((len(actions) - t) / hz if collided else np.inf)
    finally:
        sim.close()
    arrays = {k: np.array(v) for k, v in rows.items() if v}
    decisive, agrees = arrays["decisive"], arrays["agrees"]
    late = arrays["to_collision_s"] <= BEFORE_COLLISION_S

    def share(mask: np.ndarray) -> float | None:
        return float(agrees[mask].mean()) if mask.any() else None

    return {**_prediction_summary(arrays, oracle, late, None if policy is None else policy.network), **{
        "evaluation": str(folder),
        "look": sim.env.config.world.look,
        "policy": summary["policy"].get("policy"),
        "oracle": str(oracle),
        "decision_hz": hz,
        "steps": len(agrees),
        "agreement": share(np.ones_like(agrees)),
        "decisive_steps": int(decisive.sum()),
        "agreement_decisive": share(decisive),
        "steps_before_collision": int(late.sum()),
        "agreement_before_collision": share(late),
        "agreement_before_collision_decisive": share(late & decisive),
        "collisions": len(hits),
        "collisions_with_pillar": hits.count("pillar"),
        "progress_mean": summary["summary"]["progress_mean"],
        "distance_to_collision_mean": summary["summary"]["distance_to_collision_mean"],
    }}, arrays


def _prediction_summary(
    arrays: dict[str, np.ndarray], oracle: Oracle, late: np.ndarray, network: Network | None
) -> dict[str, Any]:
    """What the re-predicted values say (by the policy's `network`), where they exist and are the
    oracle's kind of score (a depth policy against a depth oracle of its lookahead): how far each
    candidate's predicted score is from
    the true one, how far apart the candidates are in truth and in prediction (the action's effect),
    and how often a fresh draw of pixel noise changes the policy's decision."""
    if "predicted_scores" not in arrays or network is None:
        return {}
    predicted, recorded = arrays["predicted_scores"], arrays["policy"]
    # The policy's own rule picks: a Depth-Q-Net the highest score, a Coll-Q-Net the lowest probability.
    choice = np.array(ACTIONS)[predicted.argmax(1) if network.maximise else predicted.argmin(1)]
    out: dict[str, Any] = {"same_decision_new_noise": float((choice == recorded).mean())}
    same = network.name == oracle.signal and network.comparable_scores
    if same and predicted.shape == arrays["scores"].shape:
        error, truth = np.abs(predicted - arrays["scores"]), arrays["scores"]
        for name, mask in (("", np.ones_like(late)), ("_before_collision", late)):
            if mask.any():
                out[f"score_error{name}"] = float(error[mask].mean())
                out[f"true_spread{name}"] = float(np.ptp(truth[mask], axis=1).mean())
                out[f"predicted_spread{name}"] = float(np.ptp(predicted[mask], axis=1).mean())
    return out
