"""The exact Euclidean distance transform and the 3 x 3 dilation (planner/native/distance.c) against
scipy.ndimage (distance_transform_edt, binary_dilation) and a brute-force minimum over every pair."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.ndimage import binary_dilation, distance_transform_edt

from planner.inflation import dilate_square, distance_to_nearest

DENSITIES = (0.001, 0.02, 0.2, 0.6, 0.97)


def _random_grids(seed: int, count: int):
    """Grids of 1 to 70 rows and columns (lines, single cells, wide and tall ones) at every density."""
    rng = np.random.default_rng(seed)
    for index in range(count):
        rows, cols = (int(n) for n in rng.integers(1, 71, 2))
        yield rng.random((rows, cols)) < DENSITIES[index % len(DENSITIES)]


def _brute_force(mask, sampling):
    rows, cols = np.indices(mask.shape)
    features = np.argwhere(mask)
    if len(features) == 0:
        return np.full(mask.shape, np.inf)
    d_row = (rows[..., None] - features[:, 0]) * sampling[0]
    d_col = (cols[..., None] - features[:, 1]) * sampling[1]
    return np.sqrt(d_row**2 + d_col**2).min(axis=-1)


def test_unit_sampling_equals_scipy_bit_for_bit():
    """As the planner and the world use it: squared distances are integers, so equality is exact."""
    for mask in _random_grids(1, 300):
        if not mask.any():
            continue  # scipy has no answer for a grid without features (we give inf: below)
        assert np.array_equal(distance_to_nearest(mask), distance_transform_edt(~mask))


@pytest.mark.parametrize("sampling", [(0.05, 0.05), (0.25, 0.25), (0.1, 0.3), (2.5, 0.7), (1.0, 1e-3)])
def test_sampled_grids_equal_scipy(sampling):
    for mask in _random_grids(2, 120):
        if not mask.any():
            continue
        ours = distance_to_nearest(mask, sampling)
        theirs = distance_transform_edt(~mask, sampling=sampling)
        np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=0)


@pytest.mark.slow
def test_equals_brute_force():
    for mask in _random_grids(3, 60):
        for sampling in ((1.0, 1.0), (0.3, 0.8)):
            expected = _brute_force(mask, sampling)
            np.testing.assert_allclose(distance_to_nearest(mask, sampling), expected, rtol=1e-12, atol=0)


def test_no_feature_is_infinitely_far_and_a_feature_is_at_zero():
    assert np.all(np.isinf(distance_to_nearest(np.zeros((4, 7), bool))))
    mask = np.zeros((5, 9), bool)
    mask[2, 3] = True
    distance = distance_to_nearest(mask, (0.5, 2.0))
    assert distance[2, 3] == 0.0 and distance[0, 3] == 1.0 and distance[2, 5] == 4.0
    assert distance_to_nearest(np.zeros((0, 3), bool)).shape == (0, 3)


def test_any_array_layout():
    """Non-contiguous and non-bool inputs give the same result as a C-ordered bool copy."""
    mask = np.random.default_rng(4).random((40, 30)) < 0.05
    expected = distance_to_nearest(mask)
    assert np.array_equal(distance_to_nearest(np.asfortranarray(mask)), expected)
    assert np.array_equal(distance_to_nearest(mask.astype(np.int32)), expected)
    wide = np.zeros((40, 60), bool)
    wide[:, ::2] = mask
    assert np.array_equal(distance_to_nearest(wide[:, ::2]), expected)
    with pytest.raises(ValueError, match="2-D"):
        distance_to_nearest(np.zeros(5, bool))


def test_dilation_equals_scipy():
    square = np.ones((3, 3), dtype=bool)
    for mask in _random_grids(5, 200):
        assert np.array_equal(dilate_square(mask), binary_dilation(mask, structure=square))
    assert dilate_square(np.zeros((0, 4), bool)).shape == (0, 4)


@pytest.mark.slow
def test_run_path_does_not_import_scipy():
    """The planner's search map, the inflation and the world's distance field need no scipy.ndimage
    (its import alone was ~0.15 s of every run)."""
    code = (
        "import sys\n"
        "import planner, planner.searchspace, cosim.world.distance\n"
        "grid = planner.OccupancyGrid.from_file('scenarios/maps/warehouse.yaml')\n"
        "planner.plan(grid, (6.0, 6.0), (84.0, 53.0), expansion_distance=1.0, untrusted_points=True)\n"
        "cosim.world.distance.WorldDistance(grid)\n"
        "print(sorted(m for m in sys.modules if m.startswith('scipy')))\n"
    )
    repo = Path(__file__).resolve().parents[2]
    done = subprocess.run([sys.executable, "-c", code], cwd=repo, capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"
