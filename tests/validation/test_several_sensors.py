"""Several sensors at once: an interface temperature fixes the split the flux leaves open.

On the virtual wall of ``helpers/split_wall.py`` (issue 15's acceptance): the
posterior SD of the boards' share of the wall's resistance narrows at least
threefold when the temperature at the concrete / inside-board interface is
calibrated beside the inside heat flux (measured: 0.0058 -> 0.00018, 33x, on
seed 0 with 20 training days), both outputs get their own noise level back
(within 10 % of the injected SDs), and each output's 95 % and 50 % bands cover
its measurements at their rates on the training and the test windows: within
3.5 binomial standard errors of 0.95 and 0.5 for the window's number of samples
(672 training, 144 test; the noise is white, so the samples' indicators are
close to independent given the posterior). Chains: 4 x (2000 + 1500) draws, the
flux-only posterior being a curved ridge (R-hat and ESS checked).
"""

from __future__ import annotations

import numpy as np
import pytest

from bayescal.calibration.posterior import Posterior
from split_wall import NOISE_SD, OUTPUTS, TRUTH, board_share, calibrate_split

#: One worker runs every test of this file (they share its module fixtures): `make
#: validate` spreads the tests over workers by `--dist loadgroup`.
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("several-sensors")]
Result = tuple[Posterior, dict[str, dict[str, tuple[float, float]]]]


@pytest.fixture(scope="module")
def flux_only() -> Result:
    return calibrate_split(0, OUTPUTS[:1])


@pytest.fixture(scope="module")
def both() -> Result:
    return calibrate_split(0, OUTPUTS)


def _share(post: Posterior) -> np.ndarray:
    k = {n: post.draws[..., i] for i, n in enumerate(post.names)}
    return board_share(k["k_fb"], k["k_cb"])


def test_the_interface_temperature_narrows_the_split_threefold(
    flux_only: Result, both: Result
) -> None:
    alone, together = _share(flux_only[0]), _share(both[0])
    assert alone.std() > 3.0 * together.std(), (alone.std(), together.std())
    truth = float(board_share(np.array(TRUTH["k_fb"]), np.array(TRUTH["k_cb"])))
    for draws in (alone, together):
        lo, hi = np.quantile(draws, [0.025, 0.975])
        assert lo <= truth <= hi
    assert not flux_only[0].warnings  # converged chains
    assert not both[0].warnings


def test_each_output_has_its_own_noise_and_bands(both: Result) -> None:
    post, cover = both
    sd = post.noise_sd()
    for name in OUTPUTS:
        assert np.median(sd[name]) == pytest.approx(NOISE_SD[name], rel=0.10), name
        for window, (c95, c50) in cover[name].items():
            n = 672 if window == "train" else 144
            for rate, level in ((c95, 0.95), (c50, 0.5)):
                assert abs(rate - level) < 3.5 * np.sqrt(level * (1 - level) / n), (name, window)
