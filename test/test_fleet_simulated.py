"""A simulated fleet of four axes, recorded daily for 10 s each under the same test motion:
one stable, one whose Coulomb friction creeps up to +30 % (a rail running dry), one that
grows a cogging force (a chipped magnet), one 5 % heavier (a new fixture). Each change is
alarmed at the recording where it happened, the stable axis never; the table, alarms.json
and the page of trends hold what the contract says; the caller's Dask client did the work.

Controls: an axis that does not change raises no alarm, whatever the noise and the loop.
Three stable axes, the same drive (5 N of Coulomb friction) recorded daily for 10 s, twelve
days each: open loop under the APRBS test motion with a 2 N noise on the thrust reading
itself (a force sensor, not the drive's command); under a PID position loop following a
two-sine move with an APRBS of 6 N injected into the controller's output; and under the
same loop with the thrust reading's noise too. Noise is not physics: every row is analysed
(status ok, the fitted mass and friction near the truth) and no parameter of any axis
leaves its band.

Both fleets run on the same caller's cluster (its workers also write the recordings).
"""

from __future__ import annotations

import dataclasses
import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from fleet_helpers import DAY, EPOCH, NOMINAL, drive, in_parallel, recording, stamped

import pmsm_sysid as ps
from pmsm_sysid.core.physics.closed_loop import (
    PositionLoop,
    reference_trajectory,
    run_closed_loop,
)
from pmsm_sysid.core.physics.excitation import make_excitation
from pmsm_sysid.core.physics.motor import simulate
from pmsm_sysid.core.physics.plant import Cogging, CoulombFriction
from pmsm_sysid.plots.fleet import axis_trends

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("fleet_simulated")]

BASELINE = 8  # the default
COULOMB = [1.0] * BASELINE + [1.1, 1.2, 1.3]
#: axis -> the plant of each daily recording
FLEET: dict[str, list[ps.Plant]] = {
    "/axis1": [drive()] * 12,
    "/axis2": [drive(coulomb_friction=CoulombFriction(5.0 * f)) for f in COULOMB],
    "/axis3": [drive()] * BASELINE + [drive(cogging=Cogging(1.0, 0.005))] * 2,
    "/axis4": [drive()] * BASELINE + [drive(mass_kg=2.3213 * 1.05)] * 2,
}
EXPECTED = {("/axis2", "coulomb_friction.amplitude_n", BASELINE),
            ("/axis3", "cogging.amplitude_n", BASELINE), ("/axis4", "mass_kg", BASELINE)}


def _name(axis: str, day: int) -> str:
    return f"{axis.strip('/')}_day{day:02d}"


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    import dask
    from dask.distributed import Client, LocalCluster

    from pmsm_sysid.batch.cluster import WORKER_CONFIG

    # a caller's cluster with the worker settings docs/fleet.md recommends, for both fleets
    with dask.config.set(WORKER_CONFIG), LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True,
            dashboard_address=":0") as cluster, Client(cluster) as c:
        yield c


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory, client: Any) -> Path:
    root = tmp_path_factory.mktemp("fleet") / "recordings"
    root.mkdir()
    calls, seed = [], 1000
    for k, (axis, plants) in enumerate(FLEET.items()):
        for day, plant in enumerate(plants):  # each axis at its own hour of the day
            seed += 1
            calls.append({"path": root / _name(axis, day), "plant": plant, "seed": seed,
                          "day": day + 0.1 * k, "namespace": axis})
    in_parallel(client, recording, calls)
    return root


@pytest.fixture(scope="module")
def run(bags: Path, client: Any) -> tuple[ps.FleetResult, list[dict[str, Any]], Path]:
    from dask.distributed import get_task_stream

    out = bags.parent / "out"
    with get_task_stream(client=client) as stream:
        result = ps.fleet(str(bags / "*"), plant=NOMINAL, client=client, out=out)
    return result, stream.data, out


@pytest.mark.timeout(3600)
def test_each_change_is_alarmed_where_it_happened_and_the_stable_axis_never(
        run: tuple[ps.FleetResult, list[dict[str, Any]], Path]) -> None:
    result, _, out = run
    got = {(a["axis"], a["parameter"], a["recording"]) for a in result.alarms}
    want = {(axis, p, str(out.parent / "recordings" / _name(axis, day)))
            for axis, p, day in EXPECTED}
    assert got == want, result.summary()
    states = {t.axis: t.state for t in result.trends}
    assert states == {"/axis1": "ok", "/axis2": "alarm", "/axis3": "alarm",
                      "/axis4": "alarm"}, result.summary()
    stable = next(t for t in result.trends if t.axis == "/axis1")
    assert all(not p.out for t in stable.parameters for p in t.points)


@pytest.mark.timeout(3600)
def test_the_table_has_one_row_per_recording_with_the_fitted_plant(
        run: tuple[ps.FleetResult, list[dict[str, Any]], Path]) -> None:
    result, _, out = run
    table = pq.read_table(out / "results.parquet")
    assert table.equals(result.table)
    rows = table.to_pylist()
    assert len(rows) == sum(len(p) for p in FLEET.values())
    assert [r["status"] for r in rows] == ["ok"] * len(rows), [r["error"] for r in rows]
    assert table.schema.field("start_time").type == pa.timestamp("us", tz="UTC")
    for axis, plants in FLEET.items():
        mine = [r for r in rows if r["axis"] == axis]
        assert len(mine) == len(plants)
        days = [(r["start_time"].timestamp() - EPOCH) / DAY for r in mine]
        assert days == sorted(days) and round(days[0]) == 0
        for r, plant in zip(mine, plants, strict=True):
            assert r["duration_s"] == pytest.approx(10.0, rel=1e-6)
            assert r["sample_rate_hz"] == pytest.approx(500.0, rel=1e-6)
            # the fit's mass runs about 1.5 % high on these recordings, up to 3 % beside a
            # friction change: a check that the column holds the fitted mass
            assert r["mass_kg"] == pytest.approx(plant.mass_kg, rel=0.05)
            assert r["mass_kg.std"] > 0 and r["viscous_n_per_mps.std"] > 0
            true_c = plant.coulomb_friction.amplitude_n  # type: ignore[union-attr]
            assert r["coulomb_friction.amplitude_n"] == pytest.approx(true_c, rel=0.05)
            assert r["coulomb_friction.confidence"] in ("high", "moderate", "low")
            assert "coulomb_friction" in r["effects"]
            assert r["nrmse_after"] < r["nrmse_before"]  # the nominal plant lacks friction
            if plant.cogging is None:
                assert r["cogging.amplitude_n"] is None and r["cogging.pitch_m.std"] is None
            else:
                assert r["cogging.amplitude_n"] == pytest.approx(1.0, rel=0.2)
                assert r["cogging.pitch_m"] == pytest.approx(0.005, rel=0.02)


@pytest.mark.timeout(3600)
def test_alarms_json_and_the_summary(
        run: tuple[ps.FleetResult, list[dict[str, Any]], Path]) -> None:
    result, _, out = run
    alarms = json.loads((out / "alarms.json").read_text())
    assert alarms == result.alarms
    for a in alarms:
        assert set(a) == {"axis", "parameter", "recording", "start_time", "value", "baseline",
                          "band"}
        assert re.fullmatch(r"2026-01-\d\dT\d\d:\d\d:\d\d\.\d{6}Z", a["start_time"])
        lo, hi = a["band"]
        assert lo < a["baseline"] < hi and not lo <= a["value"] <= hi
    by_param = {a["parameter"]: a for a in alarms}
    assert by_param["cogging.amplitude_n"]["baseline"] == 0.0  # a new effect
    assert by_param["coulomb_friction.amplitude_n"]["value"] > 5.2
    assert by_param["mass_kg"]["value"] > by_param["mass_kg"]["baseline"] * 1.03
    table, listed = result  # unpacks as (table, alarms)
    assert listed == alarms and table is result.table
    summary = result.to_dict()
    assert summary["rows"] == table.num_rows and summary["failed"] == 0
    assert [a["axis"] for a in summary["axes"]] == list(FLEET)
    assert [a["state"] for a in summary["axes"]] == ["ok", "alarm", "alarm", "alarm"]


@pytest.mark.timeout(3600)
def test_the_page_shows_each_axis_over_time_with_its_band_and_alarms(
        run: tuple[ps.FleetResult, list[dict[str, Any]], Path]) -> None:
    result, _, out = run
    page = (out / "index.html").read_text()
    assert not re.search(r"(src|href)=\"(?!data:|#)", page)  # self-contained
    assert page.count("<img") == len(FLEET) and page.count("data:image/png;base64,") == 4
    for axis in FLEET:
        assert f"Axis {axis}" in page
    assert "ALARM: mass_kg since 2026-01-13" in page
    for t in result.trends:
        drawn = axis_trends(t).data
        for p in t.parameters:
            d = drawn[p.parameter]
            banded = [q for q in p.points if q.lo is not None and q.hi is not None]
            assert list(d["alarms"]) == [a.start_time for a in p.alarms]
            assert list(d["value"]) == [q.value for q in p.points]
            assert list(d["band_t"]) == [q.start_time for q in banded]
            assert list(d["lo"]) == [q.lo for q in banded]
            assert list(d["hi"]) == [q.hi for q in banded]
            # red exactly where a recording after the baseline is outside its band
            assert list(d["out"]) == [not q.baseline and q.lo is not None
                                      and not q.lo <= q.value <= q.hi for q in p.points]


@pytest.mark.timeout(3600)
def test_the_callers_client_did_the_work_and_stays_open(
        run: tuple[ps.FleetResult, list[dict[str, Any]], Path], client: Any) -> None:
    result, stream, _ = run
    rows = [t for t in stream if t["key"].startswith("recording_row")]
    assert len(rows) == result.table.num_rows == result.analysed
    assert client.status == "running"
    assert len({t["worker"] for t in rows}) == 2  # both workers took recordings


# ----------------------------------------------------------------------- controls

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


def _control_recording(path: Path, axis: str, seed: int, day: float) -> Path:
    plant, make = AXES[axis]
    return stamped(make(plant, seed), path, day, axis)


@pytest.fixture(scope="module")
def controls(tmp_path_factory: pytest.TempPathFactory,
             client: Any) -> tuple[ps.FleetResult, dict[str, Any]]:
    root = tmp_path_factory.mktemp("fleet_controls")
    (root / "recordings").mkdir()
    calls, seed = [], 7000
    for k, axis in enumerate(AXES):
        for day in range(DAYS):
            seed += 1
            calls.append({"path": root / "recordings" / f"{axis.strip('/')}_{day:02d}",
                          "axis": axis, "seed": seed, "day": day + 0.1 * k})
    in_parallel(client, _control_recording, calls)
    result = ps.fleet(str(root / "recordings"), plant=NOMINAL, client=client,
                      out=root / "out")
    return result, result.table.to_pydict()


@pytest.mark.timeout(3600)
def test_every_control_recording_is_analysed_near_the_truth(
        controls: tuple[ps.FleetResult, dict[str, Any]]) -> None:
    result, table = controls
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
        controls: tuple[ps.FleetResult, dict[str, Any]]) -> None:
    result, _ = controls
    assert result.alarms == []
    assert {t.axis: t.state for t in result.trends} == dict.fromkeys(AXES, "ok")
    assert all(t.recordings == DAYS for t in result.trends)
