"""Property tests of bad input through the command line (``main()`` in this process).

For plant files, numbers on the command line, JSON inputs and recordings (corrupt, truncated,
reordered, NaN-laced, huge), whatever hypothesis draws: the verb either succeeds or exits 2
with exactly one line; it never raises (no traceback), leaves no output behind when it
refuses, and never changes a file that was there before. Small ``max_examples`` and no
deadline: the machine's speed is not under test.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
import tempfile
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from reliability_helpers import SMALL, input_messages, known_data, recording, write_messages

from pmsm_sysid.cli import main
from pmsm_sysid.core.errors import PlantError
from pmsm_sysid.core.physics.plant import EFFECT_BLOCKS, Plant, plant_from_dict
from pmsm_sysid.core.physics.plant_schema import BOUNDS

SETTINGS = settings(max_examples=30, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])


def _tree(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): ("dir" if p.is_dir() else
                                       hashlib.sha256(p.read_bytes()).hexdigest())
            for p in sorted(root.rglob("*"))}


@contextmanager
def workdir() -> Iterator[Path]:
    """A scratch directory holding one precious file that must survive every call."""
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        (root / "precious.json").write_text('{"keep": true}\n')
        yield root


def run_main(capsys: pytest.CaptureFixture[str], argv: list[str], root: Path,
             outputs: tuple[str, ...] = ()) -> tuple[int, str]:
    """``main(argv)``: 0 or 2 with one line, no exception, no output left when refused, and
    nothing that was there before changed."""
    before = _tree(root)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        try:
            rc = main(argv)
        except SystemExit as exc:  # a usage error while parsing the options
            rc = exc.code  # type: ignore[assignment]
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("warning:")]
    assert rc in (0, 2), (rc, err)
    after = _tree(root)
    assert {k: v for k, v in after.items() if k in before} == before  # nothing changed
    if rc == 2:
        assert len(lines) == 1 and "Traceback" not in err, err
        assert after == before, set(after) - set(before)  # nothing written
        for out in outputs:
            assert not (root / out).exists()
    return rc, lines[0] if lines else ""


# ----------------------------------------------------------------------------- plant files

NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**30, 10**30),
    st.sampled_from([0, -1, 1e-300, 1e300, 4096, 4097, 1e5, 1e5 + 1]))
JUNK = st.one_of(st.booleans(), st.none(), st.text(max_size=8),
                 st.lists(st.integers(), max_size=3), st.dictionaries(st.text(max_size=4),
                                                                      st.integers(), max_size=2))
KEYS = sorted(set(BOUNDS) | {f.name for f in Plant.__dataclass_fields__.values()}
              | {"enabled", "harmonics", "typo_key"})


@st.composite
def plant_mappings(draw: Any) -> dict[str, Any]:
    d: dict[str, Any] = {}
    for key in draw(st.lists(st.sampled_from(KEYS), max_size=6, unique=True)):
        if key in EFFECT_BLOCKS:
            d[key] = draw(st.one_of(JUNK, st.dictionaries(st.sampled_from(KEYS),
                                                           st.one_of(NUMBERS, JUNK),
                                                           max_size=4)))
        else:
            d[key] = draw(st.one_of(NUMBERS, JUNK))
    return d


@SETTINGS
@given(plant_mappings())
def test_plant_mappings_give_a_valid_plant_or_one_line(d: dict[str, Any]) -> None:
    try:
        p = plant_from_dict(d)
    except PlantError as exc:
        assert "\n" not in str(exc) and str(exc)
        return
    for name, value in vars(p).items():  # every accepted number within its bounds
        if name in BOUNDS:
            b = BOUNDS[name]
            assert math.isfinite(value) and b.low <= value <= b.high, (name, value)


@SETTINGS
@given(st.one_of(plant_mappings().map(lambda d: json.dumps(d, allow_nan=True)),
                 st.text(max_size=200), st.binary(max_size=200).map(lambda b: b.decode("latin-1"))))
def test_plant_files_through_the_cli(capsys: pytest.CaptureFixture[str], text: str) -> None:
    with workdir() as root:
        plant = root / "plant.yaml"
        plant.write_text(text, encoding="utf-8")
        # diagnose reads the plant first, then the (missing) recording: always exit 2
        rc, line = run_main(capsys, ["diagnose", "--plant", str(plant), "--real",
                                     str(root / "nobag"), "--json", str(root / "d.json")],
                            root, ("d.json",))
        assert rc == 2 and (str(plant) in line or "nobag" in line), line


# ----------------------------------------------------------------------------- CLI numbers

NUMBER_TEXT = st.one_of(
    st.sampled_from(["inf", "-inf", "nan", "1e12", "1e308", "-0", "0", "-1", "1.5", "", " ",
                     "0x10", "1_000", "9" * 40, "1e-320", "10:5", "5:5", "-3:2", "1:2:3"]),
    st.floats().map(repr), st.integers(-10**20, 10**20).map(str), st.text(max_size=6))
OPTIONS = [
    (["identify", "{nobag}", "--json", "{out}"], ["--ny", "--nu", "--terms", "--delay",
                                                  "--corr-lags", "--estimate", "--validate",
                                                  "--rho"]),
    (["gfrf", "{nobag}", "--json", "{out}"], ["--grid", "--at", "--orders"]),
    (["simulate", "--plant", "{nobag}", "--out", "{out}"], ["--duration", "--seed",
                                                           "--amplitude"]),
    (["run", "--plant", "{nobag}", "--json", "{out}"], ["--duration", "--seed", "--hop",
                                                       "--window", "--wait", "--rate",
                                                       "--amplitude"]),
    (["record", "--out", "{out}", "--namespace", "bad ns"], ["--duration", "--depth"]),
    (["replay", "{nobag}", "--json", "{out}"], ["--rate", "--loop", "--wait", "--burst",
                                                "--drain-rate"]),
]


@SETTINGS
@given(st.sampled_from([(v, o) for v, opts in OPTIONS for o in opts]), NUMBER_TEXT)
def test_numbers_on_the_command_line(capsys: pytest.CaptureFixture[str],
                                     verb_option: tuple[list[str], str], text: str) -> None:
    verb, option = verb_option
    with workdir() as root:
        argv = [a.replace("{nobag}", str(root / "nobag")).replace("{out}", str(root / "out"))
                for a in verb]
        rc, _ = run_main(capsys, [*argv, f"{option}={text}"], root, ("out",))
        assert rc == 2  # the input does not exist: refused, whatever the number


# ----------------------------------------------------------------------------- JSON inputs

JSON = st.recursive(st.none() | st.booleans() | st.floats(allow_nan=False) | st.text(max_size=6)
                    | st.integers(),
                    lambda inner: st.lists(inner, max_size=4)
                    | st.dictionaries(st.sampled_from(["terms", "last_model", "name",
                                                       "estimate", "excitation", "x"]),
                                      inner, max_size=4),
                    max_leaves=12)


@SETTINGS
@given(st.one_of(JSON.map(json.dumps), st.binary(max_size=100).map(bytes.hex),
                 st.integers(1, 20000).map(lambda n: "[" * n + "]" * n)),
       st.sampled_from(["gfrf", "report"]))
def test_json_inputs(capsys: pytest.CaptureFixture[str], text: str, verb: str) -> None:
    with workdir() as root:
        src = root / "in.json"
        src.write_text(text)
        argv = [verb, str(src), "--json", str(root / "o.json")]
        if verb == "report":
            argv += ["--out", str(root / "r")]
        run_main(capsys, argv, root, ("o.json", "r"))


# ----------------------------------------------------------------------------- recordings


@pytest.fixture(scope="module")
def clean_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    u, y = known_data(2500)
    return write_messages(tmp_path_factory.mktemp("clean") / "bag",
                          input_messages(recording(u, y)))


@st.composite
def damage(draw: Any) -> tuple[str, int, bytes]:
    kind = draw(st.sampled_from(["truncate", "flip", "metadata", "zero"]))
    return kind, draw(st.integers(0, 10**6)), draw(st.binary(min_size=1, max_size=64))


@SETTINGS
@given(damage())
def test_damaged_recordings(capsys: pytest.CaptureFixture[str], clean_bag: Path,
                            how: tuple[str, int, bytes]) -> None:
    kind, at, junk = how
    with workdir() as root:
        bag = root / "bag"
        shutil.copytree(clean_bag, bag)
        store = next(bag.glob("*.mcap"))
        data = store.read_bytes()
        if kind == "truncate":
            store.write_bytes(data[: at % len(data)])
        elif kind == "flip":
            i = at % len(data)
            store.write_bytes(data[:i] + junk + data[i + len(junk):])
        elif kind == "metadata":
            (bag / "metadata.yaml").write_bytes(junk)
        else:
            store.write_bytes(b"")
        run_main(capsys, ["identify", str(bag), *SMALL, "--estimate", "100:1000",
                          "--validate", "1200:2000", "--json", str(root / "m.json")],
                 root, ("m.json",))


@st.composite
def laced(draw: Any) -> tuple[list[tuple[str, int, int, float]], str]:
    u, y = known_data(1500)
    msgs = input_messages(recording(u, y))
    what = draw(st.sampled_from(["nan", "huge", "reorder", "backwards"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    idx = rng.choice(len(msgs), size=draw(st.integers(1, 20)), replace=False)
    for i in idx:
        s, recv, stamp, v = msgs[i]
        if what == "nan":
            msgs[i] = (s, recv, stamp, float(rng.choice([np.nan, np.inf, -np.inf])))
        elif what == "huge":
            msgs[i] = (s, recv, stamp, float(rng.choice([1e300, -1e300, 1e154])))
        elif what == "backwards":
            msgs[i] = (s, recv, stamp - int(rng.integers(1, 10**10)), v)
    if what == "reorder":
        for i in idx[:-1]:
            j = min(len(msgs) - 1, i + int(rng.integers(1, 200)))
            msgs[i], msgs[j] = msgs[j], msgs[i]
    return msgs, what


@pytest.mark.slow
@SETTINGS
@given(laced())
def test_nan_laced_reordered_and_huge_recordings(capsys: pytest.CaptureFixture[str],
                                                 case: tuple[list[Any], str]) -> None:
    msgs, what = case
    with workdir() as root:
        bag = write_messages(root / "bag", msgs)
        rc, line = run_main(capsys, ["identify", str(bag), *SMALL, "--estimate", "100:700",
                                     "--validate", "800:1400", "--json",
                                     str(root / "m.json")], root, ("m.json",))
        if rc == 2 and what == "nan" and "non-finite" not in line:
            assert "outside the recording" in line or "too few" in line, line
