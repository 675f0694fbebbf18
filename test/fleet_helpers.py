"""Shared pieces of the fleet tests: simulated recordings of a drive axis (10 s, a drive's
noise, stamped at a given date), written one by one or in parallel on a Dask cluster."""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pmsm_sysid as ps
from pmsm_sysid.core.physics.plant import CoulombFriction

EXE = Path(sys.executable).with_name("pmsm-sysid")
REPO = Path(__file__).resolve().parents[1]
NOMINAL = REPO / "plants" / "nominal.yaml"
DAY = 86400.0
#: 2026-01-05 00:00 UTC: the first recording of every simulated fleet
EPOCH = 1_767_571_200.0


def drive(**changes: Any) -> ps.Plant:
    """The packaged drive plant (Table 1 motor, a 1 um scale's noise, 1 N process force)
    with 5 N of Coulomb friction, as a linear axis on a rail has, and ``changes``."""
    base = ps.Plant.from_yaml(REPO / "pmsm_sysid" / "data" / "drive.yaml")
    return dataclasses.replace(base, **{"coulomb_friction": CoulombFriction(5.0), **changes})


def recording(path: Path, plant: ps.Plant, seed: int, day: float, *,
              namespace: str = "/pmsm", duration: float = 10.0) -> Path:
    """A recording of ``plant`` under the APRBS excitation (random steps moving the axis
    over its stroke), starting ``day`` days after :data:`EPOCH`."""
    rec = ps.simulate(plant, excitation="aprbs", duration=duration, seed=seed)
    return stamped(rec, path, day, namespace)


def stamped(rec: ps.Recording, path: Path, day: float, namespace: str) -> Path:
    """``rec`` written to ``path`` as starting ``day`` days after :data:`EPOCH`."""
    rec = dataclasses.replace(rec, t=rec.t + EPOCH + day * DAY)
    return ps.write_bag(rec, path, namespace=namespace)


def in_parallel(client: Any, make: Callable[..., Path],
                calls: Sequence[dict[str, Any]]) -> list[Path]:
    """``[make(**kwargs) for kwargs in calls]``, run on the workers of ``client`` (each
    recording is simulated and written by one of them)."""
    futures = [client.submit(make, pure=False, **kwargs) for kwargs in calls]
    paths: list[Path] = client.gather(futures)
    return paths
