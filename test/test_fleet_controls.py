"""Controls: an axis that does not change raises no alarm, whatever the noise and the loop.

Three stable axes, the same drive (5 N of Coulomb friction) recorded daily for 10 s, twelve
days each: open loop under the APRBS test motion with a 2 N noise on the thrust reading
itself (a force sensor, not the drive's command); under a PID position loop following a
two-sine move with an APRBS of 6 N injected into the controller's output; and under the
same loop with the thrust reading's noise too. Noise is not physics: every row is analysed
(status ok, the fitted mass and friction near the truth) and no parameter of any axis
leaves its band.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest
from fleet_helpers import DAY, EPOCH, NOMINAL, drive

import pmsm_sysid as ps
from pmsm_sysid.core.physics.closed_loop import (
    PositionLoop,
    reference_trajectory,
    run_closed_loop,
)
from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("fleet_controls")]

DAYS = 12
SECONDS = 10.0
TRUTH = drive()
NOISY = dataclasses.replace(TRUTH, noise=dataclasses.replace(TRUTH.noise, thrust_std=2.0))


def _open_loop(plant: ps.Plant, seed: int) -> Any:
    n = round(SECONDS * plant.sample_rate_hz)
    return simulate(plant, make_excitation("aprbs", n, plant.sample_rate_hz, seed=seed),
                    seed=seed)


def _closed_loop(plant: ps.Plant, seed: int) -> Any:
    fs = plant.sample_rate_hz
    n = round(SECONDS * fs)
    ref = reference_trajectory(n, fs, (0.02, 0.004), (0.4, 1.7))
    loop = PositionLoop.for_bandwidth(dataclasses.replace(plant, noise=None), 15.0)
    inject = make_excitation("aprbs", n, fs, seed=seed, amplitude_n=6.0)
    return run_closed_loop(plant, ref, loop, seed=seed, injection=inject)


AXES = {"/open_thrust_noise": (NOISY, _open_loop), "/closed": (TRUTH, _closed_loop),
        "/closed_thrust_noise": (NOISY, _closed_loop)}


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[ps.FleetResult, dict[str, Any]]:
    root = tmp_path_factory.mktemp("fleet_controls")
    (root / "recordings").mkdir()
    seed = 7000
    for k, (axis, (plant, make)) in enumerate(AXES.items()):
        for day in range(DAYS):
            seed += 1
            rec = make(plant, seed)
            rec = dataclasses.replace(rec, t=rec.t + EPOCH + (day + 0.1 * k) * DAY)
            ps.write_bag(rec, root / "recordings" / f"{axis.strip('/')}_{day:02d}",
                         namespace=axis)
    result = ps.fleet(str(root / "recordings"), plant=NOMINAL, workers=2, out=root / "out")
    return result, result.table.to_pydict()


@pytest.mark.timeout(3600)
def test_every_control_recording_is_analysed_near_the_truth(
        run: tuple[ps.FleetResult, dict[str, Any]]) -> None:
    result, table = run
    assert result.table.num_rows == DAYS * len(AXES)
    assert set(table["status"]) == {"ok"}, [e for e in table["error"] if e]
    axis = np.array(table["axis"])
    mass, mass_std = np.array(table["mass_kg"]), np.array(table["mass_kg.std"])
    coulomb = np.array(table["coulomb_friction.amplitude_n"], dtype=float)
    coulomb_std = np.array(table["coulomb_friction.amplitude_n.std"], dtype=float)
    assert np.all(coulomb_std > 0) and np.all(mass_std < 0.15 * TRUTH.mass_kg), mass_std
    # a clean thrust reading under the loop: the mass within 4 of its stated standard
    # errors of the truth, the Coulomb amplitude within 5 %
    clean = axis == "/closed"
    assert np.all(np.abs(mass - TRUTH.mass_kg)[clean] < 4 * mass_std[clean]), mass[clean]
    assert np.all(np.abs(coulomb[clean] / 5.0 - 1) < 0.05), coulomb[clean]
    # a noisy thrust reading (2 N): a day's fit may be off by more than its stated error
    # says (a known limit of fit-plant under such noise: up to +25 % in mass under the
    # loop, -19 % in Coulomb friction open loop), never by a sign or a factor; the
    # baseline's spread, not the stated error, sets the axis's band (next test)
    assert np.all(np.abs(mass / TRUTH.mass_kg - 1) < 0.35), mass
    assert np.all(np.abs(coulomb / 5.0 - 1) < 0.25), coulomb
    assert np.median(np.abs(coulomb / 5.0 - 1)) < 0.05, coulomb


@pytest.mark.timeout(3600)
def test_a_stable_axis_raises_no_alarm_whatever_the_noise_and_the_loop(
        run: tuple[ps.FleetResult, dict[str, Any]]) -> None:
    result, _ = run
    assert result.alarms == []
    assert {t.axis: t.state for t in result.trends} == dict.fromkeys(AXES, "ok")
    assert all(t.recordings == DAYS for t in result.trends)
