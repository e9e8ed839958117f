"""The depth heuristic expert and the OU exploration policy."""

import numpy as np
import pytest

from depthq.control.heuristic import DepthHeuristic
from depthq.control.ou import OUConfig, OUPolicy
from depthq.control.policy import Policy


def obs_with(scan: np.ndarray) -> dict:
    return {"scan": scan.astype(np.float32)}


def test_heuristic_goes_straight_when_nothing_is_in_range():
    assert DepthHeuristic().act(obs_with(np.full(360, np.inf))) == 0.0


@pytest.mark.parametrize(
    "close_bearings, expected",
    [
        ([10], 1.0),  # obstacle in the centre sector, left is farther than right → left
        ([-30, 5], 1.0),
        ([30, 5], -1.0),
        ([30, -30], 0.0),
    ],
)
def test_heuristic_steers_towards_the_farthest_sector(close_bearings, expected):
    scan = np.full(360, np.inf)
    scan[np.arange(-50, 51) % 360] = 3.0
    for b in close_bearings:
        scan[b % 360] = 0.5
    if close_bearings == [10]:
        scan[-40 % 360] = 2.0  # right is nearer than left
    assert DepthHeuristic().act(obs_with(scan)) == expected


def test_heuristic_ignores_invalid_readings():
    scan = np.full(360, np.inf)
    scan[0] = 0.0
    scan[1] = np.nan
    assert DepthHeuristic().act(obs_with(scan)) == 0.0


def test_ou_restarts_at_zero_and_follows_the_recursion_unclipped():
    config = OUConfig()
    policy = OUPolicy(config, seed=7)
    actions = [policy.act(None) for _ in range(200)]
    rng = np.random.default_rng(7)
    x, expected = 0.0, []
    for _ in range(200):
        x += 0.05 * (0 - x) + 1.0 * rng.standard_normal()
        expected.append(0.3 * x)  # the first command is already 0.3·N(0, 1); never clipped
    np.testing.assert_allclose(actions, expected)
    assert actions[0] != 0.0 and max(abs(a) for a in actions) > 1.0
    policy.reset(7)
    assert [policy.act(None) for _ in range(200)] == actions
    assert isinstance(policy, Policy)
