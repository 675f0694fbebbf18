"""Any length: a recording longer than ``max_samples`` is used in spans spread over it.

Checked against the whole-data computation: the equation data, candidate columns, Grams and
replays of the spans are the spans' own, concatenated (nothing crosses a gap); the Grams
accumulated chunk by chunk equal the ones of all columns at once; a bag is read span by
span into exactly the samples a whole read gives there; a diagnosis on spans finds what
the whole recording shows, names nothing on controls, and says what part it used.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy import stats

import pmsm_sysid as ps
from pmsm_sysid.bagio import read_recording, write_recording
from pmsm_sysid.bagio.cdr import encode_stamped
from pmsm_sysid.bagio.common import DEFAULT_QOS, FRAME_ID, connection_args
from pmsm_sysid.bagio.spans import read_excerpt
from pmsm_sysid.cli import main
from pmsm_sysid.core.discrepancy import DiagnoseOptions, diagnose
from pmsm_sysid.core.discrepancy.locate import line_dof, strongest_line
from pmsm_sysid.core.discrepancy.resim import compare, replay
from pmsm_sysid.core.discrepancy.scenarios import make_recording
from pmsm_sysid.core.errors import DataError
from pmsm_sysid.core.physics.closed_loop import PositionLoop, reference_trajectory, run_closed_loop
from pmsm_sysid.core.physics.excitation import ExcitationSource, make_excitation
from pmsm_sysid.core.physics.motor import simulate, simulate_blocks
from pmsm_sysid.core.physics.plant import Cogging, Noise, ThrustLag, nominal_plant
from pmsm_sysid.core.plantfit.kinematics import equation_data, thinned, thinned_times
from pmsm_sysid.core.plantfit.library import (
    Effect,
    Family,
    family_chunks,
    family_columns,
    raw_columns,
)
from pmsm_sysid.core.plantfit.parts import equation_data_parts
from pmsm_sysid.core.plantfit.select import Candidates
from pmsm_sysid.core.recording.spans import excerpt_of, plan_spans

FS = 500.0
NOISE = Noise(speed_std=0.002, position_std=5e-6, force_std=1.0)
SPANS = ((0, 3000), (5000, 8000), (9000, 12000))
BUDGET = 20_000  # the smallest budget: ten spans of 2000 samples


def _recording(n: int = 12_000, seed: int = 2) -> ps.Recording:
    truth = nominal_plant().with_effects(noise=NOISE, cogging=Cogging(0.8, 0.007, 0.3))
    thrust = make_excitation("multisine", n, FS, seed=seed) \
        + 6.0 * np.cos(2 * np.pi * 0.5 * np.arange(n) / FS)
    return simulate(truth, thrust, seed=seed)


def test_spans_cover_a_long_recording_evenly() -> None:
    assert plan_spans(50_000, 120_000) == ((0, 50_000),)
    spans = plan_spans(3_600_000, 120_000)
    assert len(spans) == 10 and {b - a for a, b in spans} == {12_000}
    assert spans[0][0] == 0 and spans[-1][1] == 3_600_000  # from the start to the end
    assert np.ptp(np.diff([a for a, _ in spans])) <= 1  # evenly spread
    split = plan_spans(3_600_000, 120_000, split=0.7)
    cut = 2_520_000
    est = [s for s in split if s[1] <= cut]
    held = [s for s in split if s[0] >= cut]
    assert len(est) == 7 and len(held) == 3 and len(split) == 10  # none across the cut
    assert est[0][0] == 0 and est[-1][1] == cut and held[0][0] == cut
    assert held[-1][1] == 3_600_000
    with pytest.raises(DataError, match="at least 20000"):
        plan_spans(1_000_000, 10_000)


def test_equation_data_of_spans_are_the_spans_own() -> None:
    rec = _recording()
    ex = excerpt_of(rec, SPANS)
    assert ex.total == len(rec) and not ex.whole and ex.ranges() == SPANS
    joined = equation_data_parts(nominal_plant(), ex.parts, mode="speed")
    own = [equation_data(nominal_plant(), p, joined.filt, "speed",
                         speed=(joined.speed_noise_mps, joined.prior)) for p in ex.parts]
    np.testing.assert_array_equal(joined.y, np.concatenate([d.y for d in own]))
    np.testing.assert_array_equal(thinned_times(joined),
                                  np.concatenate([thinned_times(d) for d in own]))
    np.testing.assert_array_equal(thinned(joined, joined.x),
                                  np.concatenate([thinned(d, d.x) for d in own]))
    for e in (Effect("cogging", pitch_m=0.007), Effect("thrust_lag"),
              Effect("coulomb_friction"), Effect("mass_error")):
        np.testing.assert_array_equal(
            joined.project(raw_columns(e, joined)),
            np.concatenate([d.project(raw_columns(e, d)) for d in own]), err_msg=e.name)
    # an exact lag of the command: the interval force is taken within each span
    np.testing.assert_array_equal(joined.forced(tau=4e-4, delay=3e-3),
                                  np.concatenate([d.forced(4e-4, 3e-3) for d in own]))
    # Grams accumulated over the spans equal the Gram of the joined columns
    fam = Family("cogging", tuple(Effect("cogging", pitch_m=p)
                                  for p in np.linspace(0.004, 0.012, 40)), 10.0)
    cols = family_columns(fam, joined)
    gram = np.einsum("knm,knp->kmp", cols, cols)
    parts = sum(np.einsum("knm,knp->kmp", c, c) for c in (family_columns(fam, d) for d in own))
    np.testing.assert_allclose(gram, parts, rtol=1e-12)


def test_candidate_grams_chunk_by_chunk_equal_all_columns_at_once() -> None:
    data = equation_data(nominal_plant(), _recording(6000))
    cands = Candidates.build(data)
    assert any(len(f.members) > 16 for f in cands.families)  # several chunks
    for fam, cols, gram, gy in zip(cands.families, cands.cols, cands.grams, cands.gys,
                                   strict=True):
        whole = family_columns(fam, data)
        np.testing.assert_array_equal(cols, whole.astype(np.float32))
        # the same sums, in another order of the summation (vectorised): rounding only
        np.testing.assert_allclose(gram, np.einsum("knm,knp->kmp", whole, whole), rtol=1e-13)
        np.testing.assert_allclose(gy, np.einsum("knm,n->km", whole, data.y), rtol=1e-13,
                                   atol=1e-13 * float(np.abs(gy).max()))
        assert sum(len(c) for _, c in family_chunks(fam, data)) == len(fam.members)


def test_replay_of_spans_restarts_in_each_span() -> None:
    rec = _recording()
    ex = excerpt_of(rec, SPANS)
    plant = nominal_plant()
    other = plant.with_effects(cogging=Cogging(0.8, 0.007, 0.3))
    sizes = ex.lengths
    cmp = compare(plant, other, ex.joined, None, sizes)
    alone = [replay(plant, p, cmp.horizon.horizon_s) for p in ex.parts]
    np.testing.assert_array_equal(cmp.before.speed, np.concatenate([r.speed for r in alone]))
    # every span starts a horizon: the first sample of each is the measured state
    starts = np.cumsum([0, *sizes[:-1]])
    np.testing.assert_array_equal(cmp.after.speed[starts], ex.joined.speed[starts])
    assert cmp.verdict == "better"  # the true cogging replays better


def test_a_line_is_found_in_spans_and_noise_keeps_its_level() -> None:
    rng = np.random.default_rng(5)
    sizes = (600,) * 10
    t = np.concatenate([k * 40.0 + np.arange(600) / 100.0 for k in range(10)])  # gaps
    dof = line_dof(len(sizes))
    alarms = 0
    for _ in range(100):
        f, _, ratio, bins, _ = strongest_line(rng.standard_normal(6000), t, 100.0, None,
                                              sizes)
        logp = stats.f.logsf(ratio, *dof) / np.log(10) + np.log10(bins)
        alarms += logp < np.log10(0.05)
    assert alarms <= 12  # the 5 % level (binomial: 5 expected, 12 at p ~ 0.003)
    r = 0.5 * np.sin(2 * np.pi * 7.3 * t) + rng.standard_normal(6000)
    f, _, ratio, bins, _ = strongest_line(r, t, 100.0, None, sizes)
    assert f == pytest.approx(7.3, abs=0.05)
    assert stats.f.logsf(ratio, *dof) / np.log(10) + np.log10(bins) < -6


def test_simulate_in_blocks_gives_the_same_numbers() -> None:
    plant = nominal_plant().with_effects(noise=NOISE, thrust_lag=ThrustLag(4e-4))
    src = ExcitationSource("aprbs", FS, seed=3)
    whole = simulate(plant, src.block(0, 2500), seed=3)
    blocks = list(simulate_blocks(plant, src.block, 2500, seed=3, block=1000))
    assert [len(b) for b in blocks] == [1000, 1000, 500]
    for name in ("t", "thrust", "speed", "position"):
        np.testing.assert_array_equal(np.concatenate([getattr(b, name) for b in blocks]),
                                      getattr(whole, name))


def _bag_with_log_times(path: Path, rec: ps.Recording, log_ns: np.ndarray) -> None:
    """The three topics stamped ``rec.t``, logged at ``log_ns`` (a recorder's delay)."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from pmsm_sysid import topics as tp

    stamps = np.round(rec.t * 1e9).astype(np.int64)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = []
        for name in ("thrust", "speed", "position"):
            msgtype = tp.INPUT_TYPES[name]
            msgdef, digest = connection_args(msgtype)
            conns.append((writer.add_connection(tp.input_topic("/pmsm", name), msgtype,
                                                msgdef=msgdef, rihs01=digest,
                                                offered_qos_profiles=[DEFAULT_QOS]),
                          msgtype, rec.signal(name).tolist()))
        for k, (stamp, logged) in enumerate(zip(stamps.tolist(), log_ns.tolist(),
                                                strict=True)):
            for conn, msgtype, values in conns:
                writer.write(conn, logged, encode_stamped(msgtype, stamp, FRAME_ID, values[k]))


@pytest.mark.slow
def test_a_bag_is_read_span_by_span(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from pmsm_sysid.bagio import spans

    looked_up: list[Path] = []  # the bags whose first and last stamps were read
    ends = spans._ends

    def counted(path: Path, *args: Any) -> tuple[int, int, int]:
        looked_up.append(path)
        return ends(path, *args)

    monkeypatch.setattr(spans, "_ends", counted)
    rec = _recording(30_000)
    stamp_ns = np.round(rec.t * 1e9).astype(np.int64)
    bags = {"stamped": tmp_path / "stamped", "late": tmp_path / "late",
            "drifting": tmp_path / "drifting"}
    write_recording(bags["stamped"], rec)
    _bag_with_log_times(bags["late"], rec, stamp_ns + 30_000_000_000)  # 30 s behind
    _bag_with_log_times(bags["drifting"], rec, stamp_ns * 13 // 10)  # 18 s behind at the end
    whole = read_recording(bags["stamped"]).recording
    plan = plan_spans(len(rec), BUDGET, 0.7)
    for name, bag in bags.items():
        ex = read_excerpt(bag, max_samples=BUDGET, split=0.7)
        assert ex.total == len(rec) and ex.ranges() == plan, name
        for (a, b), part in zip(ex.ranges(), ex.parts, strict=True):
            for signal in ("t", "thrust", "speed", "position"):
                np.testing.assert_array_equal(getattr(part, signal),
                                              getattr(whole, signal)[a:b], err_msg=name)
    assert looked_up == list(bags.values())  # to plan the spans
    small = read_excerpt(bags["stamped"], max_samples=40_000)
    assert small.whole and small.used == len(rec)
    assert len(looked_up) == len(bags)  # read whole: its ends are not needed


def _closed_loop_control(seconds: float, seed: int) -> ps.Recording:
    n = round(seconds * FS)
    ref = reference_trajectory(n, FS, (0.02, 0.004), (0.4, 1.7))
    plant = nominal_plant().with_effects(noise=NOISE)
    return run_closed_loop(plant, ref, PositionLoop.for_bandwidth(nominal_plant(), 15.0),
                           seed=seed)


@pytest.mark.slow
def test_a_diagnosis_on_spans_finds_what_the_whole_recording_shows() -> None:
    rec = make_recording("cogging", seed=3, duration_s=60.0)  # 30 000 samples
    whole = diagnose(nominal_plant(), rec, options=DiagnoseOptions(gfrf=False))
    spans = diagnose(nominal_plant(), rec,
                     options=DiagnoseOptions(gfrf=False, max_samples=BUDGET))
    assert whole.method["data_used"]["recording"]["whole"]
    used = spans.method["data_used"]["recording"]
    assert not used["whole"] and used["samples"] == BUDGET and used["of_samples"] == 30_000
    assert [tuple(s) for s in used["spans"]] == list(plan_spans(30_000, BUDGET, 0.7))
    assert "data used: 40 s of 60 s (20000 of 30000 samples) in 10 spans" in spans.summary()
    assert "the last 3 held out" in spans.summary()
    assert "data used" not in whole.summary()
    assert [e.name for e in whole.effects] == [e.name for e in spans.effects] == ["cogging"]
    a, b = whole.effects[0], spans.effects[0]
    for key in ("amplitude_n", "pitch_m"):  # one recording: within 4 standard errors
        err = max(a.params_std[key], b.params_std[key])
        assert abs(a.params[key] - b.params[key]) < 4 * err, key
    assert abs(b.params["pitch_m"] - 0.007) < 4 * b.params_std["pitch_m"]
    assert spans.fit["validation"]["output_error"]["verdict"] == "better"


@pytest.mark.slow
@pytest.mark.parametrize("loop", ["open", "closed"])
def test_controls_used_in_spans_name_nothing(loop: str) -> None:
    rec = (make_recording("nominal", seed=4, duration_s=60.0) if loop == "open"
           else _closed_loop_control(60.0, 4))
    d = diagnose(nominal_plant(), rec, options=DiagnoseOptions(gfrf=False, replay=False,
                                                               max_samples=BUDGET))
    assert not d.method["data_used"]["recording"]["whole"]
    assert d.method["feedback"]["closed_loop"] == (loop == "closed")
    assert [e.name for e in d.effects] == []


@pytest.mark.slow
def test_the_cli_says_what_part_of_a_long_bag_it_used(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str],
                                                        ) -> None:
    bag = tmp_path / "long"
    write_recording(bag, make_recording("cogging", seed=5, duration_s=60.0))
    out = tmp_path / "d.json"
    assert main(["diagnose", "--plant", str(Path(ps.__file__).parents[1] / "plants" /
                                            "nominal.yaml"),
                 "--real", str(bag), "--max-samples", str(BUDGET), "--no-gfrf",
                 "--no-replay", "--json", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "(30000 samples at 500 Hz, 20000 used: see 'data used')" in text
    assert "data used: 40 s of 60 s (20000 of 30000 samples) in 10 spans" in text
    used = json.loads(out.read_text())["method"]["data_used"]["recording"]
    assert used["spans"][0] == [0, 2000] and used["spans"][-1] == [28000, 30000]
    # the report repeats the diagnosis on the same spans (read again from the bag)
    assert main(["report", str(out), "--out", str(tmp_path / "rep"), "--quiet"]) == 0
    page = (tmp_path / "rep" / "index.html").read_text()
    assert "data used" in page and "20000 of 30000 samples" in page
    assert "figures not drawn" not in page
    assert (tmp_path / "rep" / "diagnose_residual_time.png").exists()
    with pytest.raises(SystemExit) as exc:
        main(["diagnose", "--plant", "x.yaml", "--real", str(bag), "--max-samples", "1000"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--max-samples" in err[0] and "at least 20000" in err[0]


def test_the_api_refuses_a_budget_below_ten_spans() -> None:
    with pytest.raises(ps.PmsmSysidError, match="max_samples"):
        ps.diagnose(None, _recording(3000), max_samples=500)
