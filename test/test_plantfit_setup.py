"""The physical fit's set-up and the open-loop noise lean, against independent truths.

* The filter, kinematic mode and loop of the physical fit are chosen on the estimation
  part -- the estimation spans of a long recording -- as the selection's segments choose
  them, so the iteration and the selection see the same equation data.
* ``noise_lean`` is ``-d/du log p(u)``: for Gaussian readings the score of a Gaussian,
  ``(u - mean) / variance`` (the kernel adds its own width to the variance).
"""

from __future__ import annotations

import numpy as np
import pytest

from pmsm_sysid.core.discrepancy.nonparam import LEAN_BANDWIDTH, noise_lean
from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import Noise, nominal_plant
from pmsm_sysid.core.plantfit.fit import FitOptions, estimation_parts, excerpt_for
from pmsm_sysid.core.plantfit.physical import fit_physical, setup

FS = 500.0


@pytest.mark.slow
def test_setup_is_chosen_on_the_estimation_spans() -> None:
    """A 24000-sample recording under a 20000-sample budget: ten spans, seven of them
    estimation; the fit's set-up is theirs, not that of all ten spans."""
    n = 24_000
    truth = nominal_plant().with_effects(noise=Noise(speed_std=0.002, position_std=5e-6,
                                                     force_std=1.0))
    thrust = make_excitation("multisine", n, FS, seed=3) \
        + 6.0 * np.cos(2 * np.pi * 0.5 * np.arange(n) / FS)
    rec = simulate(truth, thrust, seed=3)
    opts = FitOptions(max_samples=20_000)
    ex = excerpt_for(rec, opts.max_samples, opts.split)
    est = estimation_parts(ex, None, opts.split)
    assert len(ex.parts) == 10 and len(est) == 7
    pf = fit_physical(rec, None, opts)
    assert pf.setup == setup(est)
    assert pf.setup == setup(pf.segs.pieces("estimation"))
    assert pf.segs.est.filt == pf.setup.spec and pf.segs.est.mode == pf.setup.mode


def test_noise_lean_of_gaussian_readings_is_their_score() -> None:
    rng = np.random.default_rng(5)
    sigma = 7.0
    u = 3.0 + sigma * rng.standard_normal(400_000)
    iqr = 2 * 0.6745 * sigma
    var = sigma ** 2 + (LEAN_BANDWIDTH * iqr) ** 2
    at = (u > -4.0) & (u < 10.0)  # within a deviation, where the kernel estimate is sure
    x, got = u[at] - 3.0, noise_lean(u)[at]
    slope = float(x @ got / (x @ x))
    assert slope == pytest.approx(1.0 / var, rel=0.03)
    assert float(np.corrcoef(x, got)[0, 1]) > 0.9
