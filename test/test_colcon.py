"""``colcon build`` of the repository as an ament_python package, in a workspace of its own:
package.xml, the ament index marker and the message schemas land under share/, the
ament index finds the package, and the installed copy runs from the install space."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent

CHECK = """
import json, sys
from ament_index_python.packages import get_package_prefix, get_package_share_directory
import pmsm_sysid, pmsm_sysid.bagio as bagio
print(json.dumps({"share": get_package_share_directory("pmsm_sysid"),
                  "prefix": get_package_prefix("pmsm_sysid"), "module": pmsm_sysid.__file__,
                  "schemas": str(bagio.schema_dir()),
                  "types": sorted(t for t in bagio.typestore().fielddefs
                                  if t.startswith("pmsm_sysid/"))}))
"""


def test_colcon_build_installs_an_ament_python_package(tmp_path: Path) -> None:
    ws = tmp_path / "ws"
    (ws / "src").mkdir(parents=True)
    (ws / "src" / "pmsm_sysid").symlink_to(REPO)
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}
    env.pop("PYTHONPATH", None)
    proc = subprocess.run(
        [str(BIN / "colcon"), "--log-base", str(ws / "log"), "build", "--base-paths", "src",
         "--build-base", str(ws / "build"), "--install-base", str(ws / "install"),
         "--event-handlers", "console_direct-"],
        cwd=ws, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Finished <<< pmsm_sysid" in proc.stdout, proc.stdout
    prefix = ws / "install" / "pmsm_sysid"
    share = prefix / "share" / "pmsm_sysid"
    assert (share / "package.xml").read_text() == (REPO / "package.xml").read_text()
    assert sorted(p.name for p in (share / "msg_schemas").glob("*.msg")) == \
        sorted(p.name for p in (REPO / "msg_schemas").glob("*.msg"))
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" /
            "pmsm_sysid").is_file()
    site = next(prefix.glob("lib/python3*/site-packages"))
    # the ament index finds it; the installed copy (not this checkout) is imported and
    # reads its message schemas from the install space
    check_env = {**env, "AMENT_PREFIX_PATH": str(prefix), "PYTHONPATH": str(site)}
    run = subprocess.run([sys.executable, "-c", CHECK], cwd=tmp_path, env=check_env,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    import json

    got = json.loads(run.stdout)
    assert Path(got["share"]) == share and Path(got["prefix"]) == prefix
    assert Path(got["module"]).is_relative_to(site)
    assert Path(got["schemas"]) == share / "msg_schemas"
    assert "pmsm_sysid/msg/NarxModel" in got["types"]
