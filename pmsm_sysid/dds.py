"""The package's Fast DDS writer profile: acknowledgements within a tenth of a second.

A reliable writer knows that a reader in another process holds its samples when the
reader acknowledges them, and a reader acknowledges when the writer's heartbeat asks.
Fast DDS (ROS 2 Jazzy's default middleware) sends that heartbeat every 3 s, so each wait
for the last samples to be acknowledged (the end of ``run`` with a recorder, the end of
``replay``, a SIGTERM'd run) took up to 3 s per round for nothing: a 5 s recorded run
took 11.5 s. ``data/fastdds_profile.xml`` sets a 0.1 s heartbeat for every data writer and
nothing else; the same run takes 7.9 s (``bench/run_end_bench.py``).

:func:`use_packaged_profile` points Fast DDS at that file, before the process's first
ROS context is initialised (Fast DDS reads its profiles once per process), unless the
user chose a profile of their own (``FASTRTPS_DEFAULT_PROFILES_FILE``,
``FASTDDS_DEFAULT_PROFILES_FILE`` or a ``DEFAULT_FASTRTPS_PROFILES.xml`` in the working
directory) or another middleware (``RMW_IMPLEMENTATION``). No ROS import.
"""

from __future__ import annotations

import os
from pathlib import Path

PROFILE = Path(__file__).resolve().parent / "data" / "fastdds_profile.xml"
#: what Fast DDS reads a profile file's path from (Jazzy's Fast DDS 2.x reads the first)
PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")
#: profile files Fast DDS loads from the working directory by itself
LOCAL_PROFILES = ("DEFAULT_FASTRTPS_PROFILES.xml", "DEFAULT_FASTDDS_PROFILES.xml")


def use_packaged_profile() -> bool:
    """Let this process's Fast DDS use :data:`PROFILE` (module doc); True if it will."""
    if os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") not in (
            "rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp"):
        return False
    chosen = os.environ.get(PROFILE_VARIABLES[0]) or os.environ.get(PROFILE_VARIABLES[1])
    if chosen:
        return chosen == str(PROFILE)
    if any(Path(name).is_file() for name in LOCAL_PROFILES) or not PROFILE.is_file():
        return False
    os.environ[PROFILE_VARIABLES[0]] = str(PROFILE)
    return True


__all__ = ["PROFILE", "use_packaged_profile"]
