"""Bad input end to end (issue 8): every fault is one clear line or a reported diagnostic,
never a traceback and never a silently wrong model.

The recordings hold a known quadratic NARX system (``narx_systems.QUADRATIC``), so "the
model is right" is checked against the true terms and coefficients, and "the fault changed
nothing it should not" against the model of the clean recording. Error paths run the
console script as a separate process (exit code 2, one stderr line, no traceback).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from narx_systems import QUADRATIC, names, simulate
from reliability_helpers import (
    FS,
    PERIOD_NS,
    SMALL,
    assert_one_line_error,
    bag_of,
    cli_error,
    estimates,
    identify_json,
    input_messages,
    known_data,
    recording,
    run_cli,
    string_msg,
    write_messages,
)
from rosbags.rosbag2 import Writer

from pmsm_sysid import topics as tp
from pmsm_sysid.bagio import connection_args, read_recording, storage_plugin, typestore
from pmsm_sysid.bagio.cdr import encode_stamped
from pmsm_sysid.cli import main
from pmsm_sysid.core.errors import BagError

RANGES = ["--estimate", "1000:2000", "--validate", "3000:4000"]


@pytest.fixture(scope="module")
def data() -> tuple[np.ndarray, np.ndarray]:
    return known_data()


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory,
          data: tuple[np.ndarray, np.ndarray]) -> dict[str, object]:
    tmp = tmp_path_factory.mktemp("clean")
    bag = bag_of(tmp / "clean", *data)
    model, _ = identify_json(bag, tmp, *RANGES)
    return {"bag": bag, "model": model}


def _assert_true_model(d: dict[str, object]) -> None:
    got = estimates(d)  # type: ignore[arg-type]
    assert set(got) - {"const"} == names(QUADRATIC)
    for name, value in QUADRATIC.items():
        assert got[name] == pytest.approx(value, rel=0.01), name


def _same_model(a: dict[str, object], b: dict[str, object]) -> None:
    ea, eb = estimates(a), estimates(b)  # type: ignore[arg-type]
    assert ea.keys() == eb.keys()
    for k in ea:
        assert ea[k] == pytest.approx(eb[k], rel=1e-9, abs=1e-12), k


# ----------------------------------------------------------------------- samples and topics


def test_nonfinite_samples_are_dropped_counted_and_never_fitted_across(
        tmp_path: Path, data: tuple[np.ndarray, np.ndarray],
        capsys: pytest.CaptureFixture[str]) -> None:
    u, y = data[0].copy(), data[1].copy()
    position = np.cumsum(y) / FS
    u[1200], y[1500] = np.nan, np.inf
    bag = bag_of(tmp_path / "nan", u, y, position=position)
    # the two samples are dropped on reading; a window over them is refused, naming them
    assert_one_line_error(run_cli("identify", str(bag), *SMALL),
                          "estimation range 1000:2000", "non-finite thrust sample (nan)",
                          "at t = 2.4 s, message 1200 on /pmsm/thrust and 1 more")
    d, printed = identify_json(bag, tmp_path, "--estimate", "1600:2600", "--validate",
                               "3000:4000", capsys=capsys)
    _assert_true_model(d)
    assert d["alignment"]["n_nonfinite"] == 2 and d["alignment"]["n_aligned"] == 4998
    assert "warning: reading the bag: 4998 samples aligned" in printed
    assert "2 non-finite" in printed
    # diagnose uses the whole recording: one NaN thrust sample is named, not read as a gap
    # (it once said "not evenly sampled")
    cli_error(capsys, ["diagnose", "--plant", "plants/nominal.yaml", "--real", str(bag)],
              f"recording {bag} holds a non-finite thrust sample (nan) at t = 2.4 s, message "
              "1200 on /pmsm/thrust and 1 more: diagnose uses the whole recording")


def test_missing_topic_and_wrong_type_are_one_line(tmp_path: Path,
                                                   data: tuple[np.ndarray, np.ndarray],
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    msgs = input_messages(recording(*data))
    no_thrust = write_messages(tmp_path / "no_thrust", [m for m in msgs if m[0] != "thrust"],
                               extra=[("/chatter", "std_msgs/msg/String", 0, string_msg("hi"))])
    assert_one_line_error(run_cli("identify", str(no_thrust)),
                          "no <ns>/thrust + <ns>/position topics",
                          "/chatter (std_msgs/msg/String)", "/pmsm/position")
    wrong = write_messages(tmp_path / "wrong", [m for m in msgs if m[0] != "thrust"],
                           extra=[("/pmsm/thrust", "std_msgs/msg/String", 0, string_msg("9"))])
    cli_error(capsys, ["identify", str(wrong)],
              "/pmsm/thrust has type std_msgs/msg/String, expected "
              "geometry_msgs/msg/WrenchStamped")


def test_extra_topics_change_nothing(tmp_path: Path, clean: dict[str, object],
                                     data: tuple[np.ndarray, np.ndarray]) -> None:
    msgs = input_messages(recording(*data))
    extra = [("/chatter", "std_msgs/msg/String", k * PERIOD_NS, string_msg(f"m{k}"))
             for k in range(0, 5000, 7)]
    extra += [("/other/speed", "std_msgs/msg/String", 5, string_msg("not a twist"))]
    bag = write_messages(tmp_path / "extra", msgs, extra=extra)
    d, _ = identify_json(bag, tmp_path, *RANGES)
    _same_model(d, clean["model"])  # type: ignore[arg-type]
    assert d["alignment"]["n_unaligned"] == 0


# ------------------------------------------------------------------------------ stamps


def test_duplicated_reordered_and_jittered_stamps_give_the_clean_model(
        tmp_path: Path, clean: dict[str, object], data: tuple[np.ndarray, np.ndarray],
        capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(4)
    rec = recording(*data)
    nominal = np.round(rec.t * 1e9).astype(np.int64)
    jitter = {s: nominal + rng.integers(-PERIOD_NS // 5, PERIOD_NS // 5, len(rec))
              for s in ("thrust", "speed", "position")}  # +-0.2 period, each stream its own
    msgs = input_messages(rec, stamps_ns=jitter, receive_ns=nominal + 300_000)
    resent = rng.choice(len(msgs), 150, replace=False)  # sent twice (same stamp and value)
    order = list(range(len(msgs)))
    for i in sorted(resent.tolist(), reverse=True):
        order.insert(i + 1, i)
    swapped = 0
    for i in range(9, len(order) - 9, 97):  # a message overtaken by the next one on its topic
        j = i + 3
        if msgs[order[i]][0] == msgs[order[j]][0] and order[i] not in resent:
            order[i], order[j] = order[j], order[i]
            swapped += 1
    bag = write_messages(tmp_path / "messy", [(*msgs[k][:1], n, *msgs[k][2:])
                                              for n, k in enumerate(order)])
    d, printed = identify_json(bag, tmp_path, *RANGES, capsys=capsys)
    _same_model(d, clean["model"])  # type: ignore[arg-type]
    assert d["sample_rate_hz"] == pytest.approx(FS, rel=1e-3)
    a = d["alignment"]
    assert (a["n_duplicates"], a["n_out_of_order"]) == (150, swapped) and swapped > 20
    assert a["n_aligned"] == 5000 and a["n_unaligned"] == 0 and a["n_gaps"] == 0
    assert "150 duplicates" in printed and f"{swapped} messages are stamped earlier" in printed


@pytest.mark.slow
def test_gap_and_rate_change_refused_inside_a_window_fine_outside(
        tmp_path: Path, data: tuple[np.ndarray, np.ndarray],
        capsys: pytest.CaptureFixture[str]) -> None:
    u, y = data
    keep = np.r_[0:1500, 1510:5000]  # ten samples lost: later stamps jump 11 periods
    gap = bag_of(tmp_path / "gap", u[keep], y[keep], np.arange(5000)[keep] / FS)
    assert_one_line_error(run_cli("identify", str(gap), *SMALL),
                          "not evenly sampled", "after sample 1499", "step 11 periods")
    d, _ = identify_json(gap, tmp_path, "--estimate", "1600:2600", "--validate", "3000:4000")
    _assert_true_model(d)
    # 500 Hz for 3000 samples, then twice as fast, or 10 % faster: the recording's rate is
    # the 500 Hz of the longer stretch, and a window over the other stretch is refused
    for name, fs2, message in (("double", 2 * FS, "step 0.5 periods"),
                               ("ten_percent", 1.1 * FS, "sampled at 550 Hz")):
        t = np.r_[np.arange(3000) / FS, 3000 / FS + np.arange(2000) / fs2]
        rate = bag_of(tmp_path / name, u, y, t)
        cli_error(capsys, ["identify", str(rate), *SMALL, "--estimate", "3500:4500",
                           "--no-validate"], message)
        d, _ = identify_json(rate, tmp_path, "--estimate", "500:1500", "--validate",
                             "1500:2900")
        _assert_true_model(d)
        assert d["sample_rate_hz"] == FS


@pytest.mark.slow
def test_clock_jumps(tmp_path: Path, data: tuple[np.ndarray, np.ndarray],
                     capsys: pytest.CaptureFixture[str]) -> None:
    """Receive times run on; header stamps jump at sample 2500 (forward, back on the grid,
    back off the grid)."""
    rec = recording(*data)
    recv = np.round(rec.t * 1e9).astype(np.int64)

    def jumped(name: str, shift_ns: int) -> Path:
        stamps = recv + np.where(np.arange(len(rec)) >= 2500, shift_ns, 0)
        per = {s: stamps for s in ("thrust", "speed", "position")}
        return write_messages(tmp_path / name, input_messages(rec, per, recv))

    fwd = jumped("forward", 1000 * 10**9)
    assert_one_line_error(run_cli("identify", str(fwd), *SMALL, "--estimate",
                                  "2000:3000", "--no-validate"),
                          "not evenly sampled", "after sample 2499", "step 5e+05 periods")
    _assert_true_model(identify_json(fwd, tmp_path, "--estimate", "1000:2400",
                                     "--validate", "2600:4000")[0])
    # back by 200 periods on the grid: 200 stamps repeat with other values; two samples
    # claim one instant, so no time axis holds both: refused, naming the jump
    back = jumped("back", -200 * PERIOD_NS)
    cli_error(capsys, ["identify", str(back), *SMALL, "--estimate", "500:1500", "--validate",
                       "1500:2400"], "200 stamps on /pmsm/thrust repeat with other values",
              "at message 2500 the stamps jump back from t = 4.998 s to 4.6 s",
              "the time axis is broken")
    # 0.5 s back (250 stamps), as a clock reset leaves it: diagnose refuses it as well
    back = jumped("back_half_second", -250 * PERIOD_NS)
    cli_error(capsys, ["diagnose", "--plant", "plants/nominal.yaml", "--real", str(back)],
              "250 stamps on /pmsm/thrust repeat with other values", "to 4.5 s")
    # back by 200.3 periods: the two stretches interleave after sorting -> off the grid
    off = jumped("back_off_grid", -200 * PERIOD_NS - 600_000)
    cli_error(capsys, ["identify", str(off), *SMALL, "--estimate", "2000:3000",
                       "--no-validate"], "not evenly sampled", "after sample 2300")


# ------------------------------------------------------------------------------- values


@pytest.mark.slow
def test_absurd_values_refused_saturation_warned(tmp_path: Path,
                                                 data: tuple[np.ndarray, np.ndarray],
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    u, y = data
    huge = u.copy()
    huge[1500] = 1e300
    assert_one_line_error(run_cli("identify", str(bag_of(tmp_path / "huge", huge, y)),
                                  *SMALL),
                          "'thrust' reaches 1e+300: too large for a degree-2 model")
    scaled = bag_of(tmp_path / "scaled", u * 1e80, y * 1e80)
    cli_error(capsys, ["identify", str(scaled), *SMALL], "too large")
    clipped = bag_of(tmp_path / "clipped", np.clip(u, -0.6, 0.6), y)
    d, printed = identify_json(clipped, tmp_path, *RANGES, capsys=capsys)
    assert "warning: thrust sits at its maximum 0.6" in printed and "saturated" in printed
    assert any("saturated" in w for w in d["data_check"]["warnings"])
    # a two-level input sits at its extremes by design: no saturation warning
    prbs = np.where(u > 0, 1.0, -1.0)
    d, printed = identify_json(bag_of(tmp_path / "prbs", prbs, y), tmp_path, *RANGES,
                               "--degree", "1", capsys=capsys)
    assert "saturated" not in printed


# ------------------------------------------------------------------------ non-exciting data


@pytest.mark.slow
def test_non_exciting_data_says_why(tmp_path: Path, data: tuple[np.ndarray, np.ndarray],
                                    capsys: pytest.CaptureFixture[str]) -> None:
    u, y = data
    flat_out = bag_of(tmp_path / "flat_out", u, np.full_like(y, 0.25))
    assert_one_line_error(run_cli("identify", str(flat_out), *SMALL),
                          "insufficient excitation: speed is constant in the estimation data")
    flat_in = bag_of(tmp_path / "flat_in", np.full_like(u, 3.0), y)
    cli_error(capsys, ["identify", str(flat_in), *SMALL],
              "insufficient excitation: thrust is constant in the estimation data")
    cli_error(capsys, ["identify", str(bag_of(tmp_path / "short", u[:30], y[:30])), *SMALL,
                       "--estimate", "0:12", "--no-validate"],
              "12 samples are too few", "need at least 14")
    # one tone cannot excite 8 input lags: a model with a reason, and GFRF peaks unsupported
    k = np.arange(5000)
    tone = np.sin(2 * np.pi * 16.5 / FS * k)
    yt = simulate({"y(k-1)": 0.9, "u(k-1)": 0.1, "u(k-1)^2": 0.05}, tone, 1e-4)
    d, printed = identify_json(bag_of(tmp_path / "tone", tone, yt), tmp_path, "--nu", "8",
                               "--ny", "4", *RANGES, capsys=capsys)
    assert ("warning: insufficient excitation: thrust is persistently exciting of order 2 "
            "only (< nu = 8 input lags)") in printed
    assert d["data_check"]["pe_order"] == 2 and d["data_check"]["pe_sufficient"] is False
    model = tmp_path / "tone.json"
    model.write_text(json.dumps(d))
    assert main(["gfrf", str(model), "--orders", "1", "--json", str(tmp_path / "g.json")]) == 0
    g = json.loads((tmp_path / "g.json").read_text())
    ex = g["identifiability"]["excitation"]
    assert ex["broadband"] is False and ex["tones_hz"] == [pytest.approx(16.5, abs=0.5)]
    assert g["h1"]["peaks"] and all(p["supported"] is False for p in g["h1"]["peaks"])


def test_rank_deficient_candidates_are_skipped_and_reported(
        tmp_path: Path, data: tuple[np.ndarray, np.ndarray],
        capsys: pytest.CaptureFixture[str]) -> None:
    """A two-level input makes u(k-1)^2 = u(k-2)^2 = 1, the constant: 2 of the 14
    non-constant candidates are dependent, so 12 terms are the most there can be."""
    u = np.where(data[0] > 0, 1.0, -1.0)
    y = simulate({"y(k-1)": 0.5, "u(k-1)": 1.0, "y(k-1)u(k-2)": 0.2}, u, 1e-3)
    bag = bag_of(tmp_path / "prbs", u, y)
    d, printed = identify_json(bag, tmp_path, *RANGES, "--terms", "14", capsys=capsys)
    got = estimates(d)
    assert len(got) == 13 and "u(k-1)^2" not in got and "u(k-2)^2" not in got
    assert all(np.isfinite(t["std"]) for t in d["terms"])
    assert "12 terms instead of the 14 asked for" in printed and "rank-deficient" in printed
    assert d["validation"]["validation"]["r2"] > 0.999
    d, printed = identify_json(bag, tmp_path, *RANGES, "--terms", "40", capsys=capsys)
    assert "instead of the 40 asked for: there are only 14 candidates" in printed


# ------------------------------------------------------------------------------------ bags


def _topics_only(path: Path, storage: str) -> Path:
    """A finalised bag with the input topics declared and not one message."""
    with Writer(path, version=9, storage_plugin=storage_plugin(storage)) as w:
        for s in ("thrust", "position"):
            msgdef, digest = connection_args(tp.INPUT_TYPES[s])
            w.add_connection(tp.input_topic("/pmsm", s), tp.INPUT_TYPES[s], msgdef=msgdef,
                             rihs01=digest)
    return path


def _without_definitions(path: Path, msgs: list[tuple[str, int, int, float]],
                         storage: str) -> Path:
    """The input topics with empty message definitions (only the type names and hashes)."""
    store = typestore()
    with Writer(path, version=9, storage_plugin=storage_plugin(storage)) as w:
        conns = {s: w.add_connection(tp.input_topic("/pmsm", s), tp.INPUT_TYPES[s], msgdef="",
                                     rihs01=store.hash_rihs01(tp.INPUT_TYPES[s]))
                 for s in ("thrust", "speed", "position")}
        for signal, recv, stamp, value in msgs:
            w.write(conns[signal], recv,
                    encode_stamped(tp.INPUT_TYPES[signal], stamp, "pmsm", value))
    return path


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_empty_bags_and_bags_without_definitions(tmp_path: Path, storage: str,
                                                 data: tuple[np.ndarray, np.ndarray]) -> None:
    empty = write_messages(tmp_path / "empty", [], storage=storage)
    assert_one_line_error(run_cli("identify", str(empty)), "no <ns>/thrust", "no topics at all")
    with pytest.raises(BagError, match=r"no messages on /pmsm/thrust and /pmsm/position "
                                       r"\(empty recording\)"):
        read_recording(_topics_only(tmp_path / "topics_only", storage))
    rec = recording(*data)
    bare = _without_definitions(tmp_path / "bare", input_messages(rec), storage)
    back = read_recording(bare).recording  # the standard types are known: it reads the same
    for name in ("thrust", "speed", "position"):
        np.testing.assert_array_equal(back.signal(name), rec.signal(name))


# ---------------------------------------------------------------- options, plants and GFRF


@pytest.mark.parametrize("argv,fragments", [
    (["--ny", "100000"], ["argument --ny: must be at most 10000, got 100000"]),
    (["--ny", "9000"], ["samples are too few", "maximum lag 9000"]),
    (["--ny", "1000", "--nu", "1000"], ["candidate terms", "exceed the limit of 200000"]),
    (["--ny", "0", "--nu", "0"], ["ny + nu > 0"]),
    (["--delay", "0"], ["delay must be >= 1"]),
    (["--degree", "4"], ["invalid choice: 4"]),
    ([*SMALL, "--corr-lags", "0"], ["argument --corr-lags: must be >= 1, got 0"]),
    (["--estimate", "4000:6000"], ["estimation range 4000:6000 is outside the recording "
                                   "(0:5000)"]),
    ([*SMALL, "--validate", "4900:5001"], ["validation range 4900:5001 is outside"]),
    (["--estimate", "10:5"], ["need 0 <= START < STOP, got '10:5'"]),
    (["--estimate", "1e3:2e3"], ["expected START:STOP"]),
    (["--rho", "2"], ["argument --rho: expected a number in (0, 1), got '2'"]),
    (["--frobnicate", "1"], ["unrecognized arguments: --frobnicate 1"]),
], ids=lambda v: "_".join(v) if isinstance(v, list) and v and v[0].startswith("-") else "")
def test_impossible_identify_options(clean: dict[str, object], argv: list[str],
                                     fragments: list[str],
                                     capsys: pytest.CaptureFixture[str]) -> None:
    cli_error(capsys, ["identify", str(clean["bag"]), *argv], *fragments)


@pytest.mark.ros  # run takes a plant file too
def test_bad_plant_files_one_line_in_every_verb_that_takes_one(
        tmp_path: Path, clean: dict[str, object], capsys: pytest.CaptureFixture[str]) -> None:
    negative = tmp_path / "negative.yaml"
    negative.write_text("mass_kg: -2.3\nviscous_n_per_mps: 32.5\n")
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text("mass_kg: 2.3\nvicsous_n_per_mps: 32.5\n")
    assert_one_line_error(run_cli("diagnose", "--plant", str(negative), "--real",
                                  str(clean["bag"])), "mass_kg must be > 0")
    cli_error(capsys, ["diagnose", "--plant", str(unknown), "--real", str(clean["bag"])],
              "unknown key 'vicsous_n_per_mps' (did you mean 'viscous_n_per_mps'?)")
    cli_error(capsys, ["simulate", "--plant", str(negative), "--out", str(tmp_path / "s")],
              "mass_kg must be > 0")
    assert not (tmp_path / "s").exists()
    cli_error(capsys, ["run", "--plant", str(unknown), "--duration", "1"],
              "unknown key 'vicsous_n_per_mps'")


def _model_file(path: Path, terms: dict[str, float], **extra: object) -> Path:
    path.write_text(json.dumps({"sample_rate_hz": 500.0, **extra, "terms": [
        {"name": n, "estimate": v} for n, v in terms.items()]}))
    return path


def test_gfrf_of_impossible_models_is_one_line(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    ok = {"y(k-1)": 0.5, "u(k-1)": 1.0, "u(k-1)^2": 0.1}
    lag = _model_file(tmp_path / "lag.json", {**ok, "y(k-5000)": 0.01})
    assert_one_line_error(run_cli("gfrf", str(lag)), "largest lag 5000 exceeds 1024")
    for fs, says in ((0.0, "sample_rate_hz must be a positive number, got 0.0"),
                     (-500.0, "sample_rate_hz must be a positive number, got -500.0"),
                     ("fast", 'sample_rate_hz must be a number, got "fast"')):
        cli_error(capsys, ["gfrf", str(_model_file(tmp_path / "fs.json", ok,
                                                   sample_rate_hz=fs))], says)
    nan = tmp_path / "nan.json"
    nan.write_text('{"terms": [{"name": "u(k-1)", "estimate": NaN}]}')
    cli_error(capsys, ["gfrf", str(nan)], "non-finite estimates")
    cli_error(capsys, ["gfrf", str(_model_file(tmp_path / "ok.json", ok)), "--grid", "5000"],
              "grid must be")


@pytest.mark.slow
def test_gfrf_of_unstable_linear_and_huge_models_is_finite(tmp_path: Path) -> None:
    """Reported, not refused: an unstable linear part (flagged), no nonlinear terms (H2 = H3
    = 0, said so), coefficients of 1e150 (finite numbers or documented nulls, never NaN)."""
    cases = {
        "unstable": ({"y(k-1)": 1.2, "u(k-1)": 1.0, "u(k-1)^2": 0.1}, "UNSTABLE"),
        "linear": ({"y(k-1)": 0.5, "u(k-1)": 1.0}, "H2 = H3 = 0"),
        "huge": ({"y(k-1)": 0.5, "u(k-1)": 1e150, "u(k-1)^2": 1e150, "u(k-1)^3": 1e150},
                 "stable"),
    }
    for name, (terms, said) in cases.items():
        proc = run_cli("gfrf", str(_model_file(tmp_path / f"{name}.json", terms)),
                       "--at", "0.1,0.2", "--json", "-")
        assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
        assert said in proc.stderr
        d = json.loads(proc.stdout)  # strict JSON: a NaN would not parse as a number
        h = d["eval"][0]["h"]
        assert all(isinstance(x, float) and np.isfinite(x) for x in h), (name, h)
        assert d["stable"] is (name != "unstable")
