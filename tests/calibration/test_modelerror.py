"""The size of the model error the data show: the discrepancy's SD against the noise SD."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from scipy import linalg

from bayescal.calibration.modelerror import (
    MODEL_ERROR_FLOOR,
    ModelErrorSize,
    discrepancy_ratios,
    discrepancy_sd,
)
from bayescal.emulator.noise import OutputNoise
from bayescal.report.trust import MISSES, trust_warnings


def _fakes(seed: int = 4) -> tuple[Any, Any, np.ndarray]:
    """Two outputs: ``a`` (6 samples, 2 basis vectors, a discrepancy over the conditions
    and of each period's own) and ``b`` (4 samples, 1 vector, none); 2 chains x 50 draws."""
    rng = np.random.default_rng(seed)
    k = linalg.block_diag(rng.normal(size=(6, 2)), rng.normal(size=(4, 1)))
    sd = rng.uniform(0.5, 2.0, 10)
    variances = rng.uniform(0.5, 3.0, 3)
    emulator = SimpleNamespace(
        basis=SimpleNamespace(k=k),
        outputs=SimpleNamespace(sd=sd),
        kernels=[SimpleNamespace(variance=v) for v in variances],
    )
    outputs = (
        OutputNoise("a", (0, 6), (0, 1), discrepancy="both", unit="W/m2", scale=1.5),
        OutputNoise("b", (6, 10), (2,), unit="degC", scale=0.3),
    )
    names = ("lambda", "lambda_star_a", "lambda_star_b", "delta_rel_a", "delta_ind_a")
    aux = np.stack(
        [
            rng.gamma(5.0, 1.0, (2, 50)),
            rng.gamma(20.0, 1.0, (2, 50)),
            rng.gamma(20.0, 1.0, (2, 50)),
            10.0 ** rng.uniform(-4, -1, (2, 50)),
            10.0 ** rng.uniform(-4, -1, (2, 50)),
        ],
        axis=-1,
    )
    lam = aux[..., 1:3]

    def noise_sd() -> dict[str, np.ndarray]:
        return {o.name: o.scale / np.sqrt(lam[..., q]) for q, o in enumerate(outputs)}

    posterior = SimpleNamespace(aux=aux, aux_names=names, noise=outputs, noise_sd=noise_sd)
    return emulator, posterior, aux


def test_the_sd_is_that_of_the_dense_covariance() -> None:
    emulator, posterior, aux = _fakes()
    got = discrepancy_sd(emulator, posterior)
    assert set(got) == {"a"}  # b has no discrepancy
    k, sd = emulator.basis.k[:6, :2], emulator.outputs.sd[:6]
    v = np.array([kern.variance for kern in emulator.kernels[:2]])
    for c in range(2):
        for s in range(50):
            r = aux[c, s, 3] + aux[c, s, 4]  # both parts add variance
            cov = np.diag(sd) @ k @ np.diag(r * v) @ k.T @ np.diag(sd)  # physical units
            assert got["a"][c, s] == pytest.approx(np.sqrt(np.trace(cov) / 6), rel=1e-12)


def test_the_sd_is_that_of_simulated_discrepancies() -> None:
    # Monte Carlo: delta_j ~ N(0, r v_j), mapped by the basis and the scales; the
    # mean square over periods and samples matches within 4 standard errors (periods
    # as the independent units).
    emulator, posterior, aux = _fakes(seed=9)
    want = discrepancy_sd(emulator, posterior)["a"][0, 0]
    rng = np.random.default_rng(1)
    r = aux[0, 0, 3] + aux[0, 0, 4]
    v = np.array([kern.variance for kern in emulator.kernels[:2]])
    weights = rng.normal(size=(200_000, 2)) * np.sqrt(r * v)
    values = (weights @ emulator.basis.k[:6, :2].T) * emulator.outputs.sd[:6]
    per_period = np.mean(values**2, axis=1)  # the periods are independent draws
    second = per_period.mean()
    se = per_period.std() / np.sqrt(per_period.size)
    assert abs(second - want**2) < 4.0 * se, (second, want**2, se)


def test_ratio_and_the_rule() -> None:
    emulator, posterior, _ = _fakes()
    (size,) = discrepancy_ratios(emulator, posterior)
    assert size.output == "a"
    assert size.unit == "W/m2"
    noise = posterior.noise_sd()["a"].reshape(-1)
    np.testing.assert_allclose(size.ratio, size.sd / noise, rtol=1e-12)
    low = ModelErrorSize("q", "W/m2", np.full(100, 0.01), np.linspace(0.001, 0.5, 100))
    high = ModelErrorSize("q", "W/m2", np.full(100, 0.3), np.linspace(0.3, 2.0, 100))
    assert not low.shown
    assert high.shown
    assert np.quantile(high.ratio, 0.025) > MODEL_ERROR_FLOOR
    # the verdict only: the SD is a process scale, not the size of the model's error
    assert high.line().startswith("q: the data show a model error (the in-likelihood")
    assert "W/m2" not in high.line()
    assert low.line() == "q: no model error shown by the in-likelihood discrepancy"


def test_the_first_screen_says_it_only_where_shown() -> None:
    low = ModelErrorSize("q", "W/m2", np.full(100, 0.01), np.linspace(0.001, 0.5, 100))
    high = ModelErrorSize("q", "W/m2", np.full(100, 0.3), np.linspace(0.3, 2.0, 100))
    assert trust_warnings(None, model_error=[low]) == ()
    (said,) = trust_warnings(None, model_error=[low, high])
    assert said == f"{high.line()}: {MISSES}"
