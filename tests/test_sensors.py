"""Depth bins and the bump rule on hand-made scans (pure functions, docs/design.md#bins)."""

import numpy as np
import pytest

from depthq.sim.sensors import BinConfig, LidarConfig, bump, depth_bins, finish_scan


def scan_of(value: float) -> np.ndarray:
    return np.full(360, value, np.float32)


def test_bins_are_left_to_right_groups_of_four_clipped_at_two_metres():
    scan = scan_of(np.inf)
    scan[51], scan[50], scan[49], scan[48] = 1.0, 1.2, 1.4, 1.6  # first bin: +51..+48 degrees
    scan[(-52) % 360] = 0.5  # last bin: -49..-52 degrees
    bins = depth_bins(scan)
    assert bins.shape == (26,)
    assert bins[0] == pytest.approx(1.3)
    assert bins[-1] == pytest.approx((0.5 + 3 * 2.0) / 4)
    assert np.all(bins[1:-1] == 2.0)  # nothing in range counts as far, clipped at 2 m


def test_invalid_readings_are_ignored_and_an_all_invalid_bin_is_nan():
    scan = scan_of(1.0)
    scan[[51, 50]] = 0.0  # invalid
    scan[[49]] = np.nan
    scan[48] = 0.6
    scan[[47, 46, 45, 44]] = 0.0
    bins = depth_bins(scan, BinConfig(invalid_as_far=False))
    assert bins[0] == pytest.approx(0.6)
    assert np.isnan(bins[1])
    assert bins[2] == pytest.approx(1.0)


def test_the_original_counts_invalid_readings_as_far():
    """The recorder stored 0 or no return as 5 m: after the 2 m clip such a reading is far, never NaN."""
    scan = scan_of(1.0)
    scan[[51, 50]] = 0.0
    scan[49] = np.nan
    scan[48] = 0.6
    scan[[47, 46, 45, 44]] = 0.0
    bins = depth_bins(scan)
    assert bins[0] == pytest.approx((2.0 + 2.0 + 2.0 + 0.6) / 4)
    assert bins[1] == 2.0
    assert not np.isnan(bins).any()


def test_bins_ignore_readings_outside_the_104_degree_window():
    scan = scan_of(np.inf)
    scan[52] = 0.3
    scan[(-53) % 360] = 0.3
    assert np.all(depth_bins(scan) == BinConfig().clip)


def test_bump_needs_a_close_group_within_45_degrees():
    scan = scan_of(np.inf)
    assert not bump(scan)
    scan[[4, 3, 2, 1]] = 0.1  # one group of 4 ahead (groups run +44..+41, ..., +4..+1), mean 0.1 < 0.2
    assert bump(scan)
    scan = scan_of(np.inf)
    scan[0] = 0.1  # a single close reading averaged with three far (clipped at 1 m) ones
    assert not bump(scan)
    scan = scan_of(0.1)
    scan[(np.arange(-45, 45)) % 360] = 0.5  # close only outside ±45°
    assert not bump(scan)


def test_finish_scan_applies_range_limits():
    rng = np.random.default_rng(0)
    raw = np.array([-1.0, 0.05, 1.0, 3.6] + [1.0] * 356)
    scan = finish_scan(raw, LidarConfig(noise_std=0.0), rng)
    assert np.isposinf(scan[0]) and scan[1] == 0.0 and scan[2] == 1.0 and np.isposinf(scan[3])
