"""``pmsm-sysid run``: simulated motor, online identifier and GFRF node in one process."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from .common import (
    MAX_AMPLITUDE_N,
    count,
    live_seconds,
    number,
    ros_name,
    seed_type,
    wait_seconds,
)

#: Most samples per fit window (200 s at 500 Hz).
MAX_WINDOW = 100_000

HELP = ("run the sim motor, identifier and GFRF nodes (and a live diagnosis) in one process "
        "(live pipeline)")
#: Output options, checked before any work starts (see common.check_outputs).
OUTPUTS = {"json": "file", "record": "bag", "report": "report"}

EPILOG = """\
examples:
  pmsm-sysid run --duration 10 --json run.json            # real time, 10 s
  pmsm-sysid run --clock sim --duration 30 --json -       # 30 s of data, as fast as it fits
  pmsm-sysid run --nodes sim --clock sim --wait 30        # motor side only (other host)
  pmsm-sysid run --nodes identifier,gfrf --duration 60    # identification side only
  pmsm-sysid run --nodes identifier,gfrf --diagnose my_sim.yaml   # a real drive on /pmsm,
                                          # diagnosed against the plant file every 10 s
  pmsm-sysid run --nodes identifier --diagnose-sim /twin  # ... against a simulator on /twin
The default excitation and plant are what the identifier's structure needs: broadband
thrust is persistently exciting for the 40 input lags, so the models hold for any input in
its band. The paper's single tones (paper-speed, paper-position) reproduce Liu et al.: the
data check warns that a tone is persistently exciting of order 2 only, so the models (and
their H1) hold at the tone and its harmonics, not elsewhere; band-limited signals (multisine,
chirp, prbs with its hold, aprbs) lie between. The change detector compares windows under the
same excitation only; on a stationary plant it stays quiet under every packaged excitation
(no false alarm in one simulated hour of each, bench/change_false_alarms.py).
The summary line leads with the verdict: pass, warning or FAIL. Each output is judged by
its windows together: the correlation tests reject a correct model in about 1 window in 20
by chance, so the output fails only when its windows fail significantly more often than
that (one-sided binomial test at 1 %, widened for the overlap of the windows, which pass
and fail together) or its latest free run fails; a chance failure of the
latest window is named as a detail of a pass.
--diagnose PLANT.yaml adds the live diagnosis: every diagnose.period_s (10 s of data) the
latest diagnose.span_s (30 s) of the inputs are diagnosed in a worker process, as
`pmsm-sysid diagnose --plant PLANT.yaml` would on a recording of them (the last 30 % held
out); the result goes to <ns>/diagnosis, the effects' numbers to <ns>/stats/diagnosis/...,
the state to /diagnostics (WARN while physics the plant lacks is present).
--diagnose-sim NAMESPACE does the same against a simulator publishing its own thrust, speed
and position under NAMESPACE, beside the drive (its latest span, aligned the same way).
--duration counts seconds of data (duration x 500 samples) when the sim node runs in this
process, in either clock; wall-clock seconds otherwise. Without it the run lasts until
Ctrl-C or SIGTERM, which stop it cleanly (results flushed, recording finalised).
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.epilog = EPILOG
    p.add_argument("--plant", metavar="PLANT.yaml", default="drive",
                   help="plant file, or the name of a packaged one (default: drive, the "
                        "paper's Table 1 motor with a 1 um scale's position and speed noise "
                        "and a 1 N process force; nominal = the same without noise)")
    p.add_argument("--excitation", default="broadband",
                   help="broadband (default: multisine 0.5-240 Hz, 60 N peak), multisine "
                        "(1-40 Hz), chirp, prbs, aprbs, paper-speed (16.5 Hz tone), "
                        "paper-position (11.5 Hz tone); see below")
    p.add_argument("--amplitude", type=number(0, MAX_AMPLITUDE_N, unit="N"),
                   default=None, metavar="N",
                   help="thrust amplitude in N (default: the excitation's own)")
    p.add_argument("--seed", type=seed_type, default=0, help="seed of noise and excitation")
    p.add_argument("--duration", type=live_seconds, default=None, metavar="S",
                   help="stop after S seconds of data (see below; default: until Ctrl-C)")
    p.add_argument("--nodes", default="sim,identifier,gfrf",
                   help="comma list of sim, identifier, gfrf (default: all three)")
    p.add_argument("--record", metavar="BAG", help="record inputs and outputs to a new bag")
    p.add_argument("--json", metavar="FILE", help="summary at exit as JSON ('-' = stdout)")
    p.add_argument("--report", metavar="DIR",
                   help="at exit, write DIR/index.html: the models over time, window by "
                        "window, and the last model (also: pmsm-sysid report SUMMARY.json)")
    p.add_argument("--clock", choices=("wall", "sim"), default="wall",
                   help="wall: real time (default); sim: stamps k/fs, faster than real time")
    p.add_argument("--rate", type=number(0, 1e6), default=1.0, metavar="R",
                   help="with --clock sim and no identifier here: R x real time (0 = max)")
    p.add_argument("--namespace", type=ros_name, default="/pmsm",
                   help="namespace of the pipeline's nodes and topics, inputs and results "
                        "(default /pmsm; one per motor)")
    p.add_argument("--wait", type=wait_seconds, default=0.0, metavar="S",
                   help="--nodes sim without identifier: wait up to S s for a subscriber "
                        "on the input topics before the first sample (default 0)")
    p.add_argument("--subscribers", type=count(1, 1000), default=1, metavar="N",
                   help="with --wait: wait for N subscribers on each input topic (default 1; "
                        "2 for an identifier that also records)")
    p.add_argument("--window", type=count(2, MAX_WINDOW), default=None,
                   help="samples per fit (default 1000)")
    p.add_argument("--hop", type=count(1, MAX_WINDOW), default=None,
                   help="samples between fits (default 250)")
    p.add_argument("--method", choices=("iofr", "ofr"), default=None,
                   help="term selection of the identifier (default ofr)")
    p.add_argument("--outputs", default=None, help="identified outputs (default speed,position)")
    ref = p.add_mutually_exclusive_group()
    ref.add_argument("--diagnose", metavar="PLANT.yaml",
                     help="add the live diagnosis against this plant file (or packaged plant "
                          "name): every diagnose.period_s, the latest diagnose.span_s of the "
                          "inputs (see below)")
    ref.add_argument("--diagnose-sim", metavar="NAMESPACE", type=ros_name,
                     help="add the live diagnosis against a simulator publishing its own "
                          "thrust, speed and position under NAMESPACE")
    p.add_argument("--set", action="append", default=[], metavar="NODE.PARAM=VALUE",
                   help="any node parameter, e.g. identifier.speed.terms=10, "
                        "sim.cogging.enabled=true, gfrf.orders=[1,2], diagnose.period_s=5 "
                        "(repeatable)")


def _value(text: str) -> Any:
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


def node_params(args: argparse.Namespace) -> dict[str, dict[str, Any]]:
    """Per-node parameter overrides from the options and ``--set``."""
    from ..core.errors import PmsmSysidError

    out: dict[str, dict[str, Any]] = {"sim": {}, "identifier": {}, "gfrf": {}, "diagnose": {}}
    ident = out["identifier"]
    for key in ("window", "hop", "method"):
        if getattr(args, key) is not None:
            ident[key] = getattr(args, key)
    if args.outputs is not None:
        ident["outputs"] = [s.strip() for s in args.outputs.split(",") if s.strip()]
    if args.amplitude is not None:
        out["sim"]["amplitude_n"] = float(args.amplitude)
    for item in args.set:
        name, sep, text = item.partition("=")
        node, dot, param = name.partition(".")
        if not sep or not dot or node not in out or not param:
            raise PmsmSysidError(f"--set takes NODE.PARAM=VALUE with NODE sim, identifier, gfrf "
                                 f"or diagnose (got '{item}')")
        out[node][param] = _value(text)
    if args.diagnose is not None:
        out["diagnose"]["plant_file"] = args.diagnose
    if args.diagnose_sim is not None:
        out["diagnose"]["sim_namespace"] = args.diagnose_sim
    return out


def _with_diagnosis(nodes: tuple[str, ...], args: argparse.Namespace,
                    params: dict[str, Any]) -> tuple[str, ...]:
    """The nodes with the diagnosis when asked for; its reference checked (one line, exit
    2) before any node starts."""
    from ..core.errors import PmsmSysidError
    from ..core.physics.plant import load_plant
    from ..nodes.diagnosis_node import DEFAULTS
    from ..topics import normalize_namespace

    for key, value in params.items():  # --set diagnose.period_s=5 means 5.0 s
        if isinstance(DEFAULTS.get(key), float) and type(value) is int:
            params[key] = float(value)
    given = params.get("plant_file") or params.get("sim_namespace")
    if not given:
        if "diagnose" in nodes or params:
            raise PmsmSysidError("the diagnosis needs a reference: --diagnose PLANT.yaml or "
                                 "--diagnose-sim NAMESPACE")
        return nodes
    if params.get("plant_file") and params.get("sim_namespace"):
        raise PmsmSysidError("--diagnose and --diagnose-sim exclude each other: the "
                             "diagnosis has one reference")
    if params.get("plant_file"):
        load_plant(str(params["plant_file"]))
    elif normalize_namespace(str(params["sim_namespace"])) == normalize_namespace(args.namespace):
        raise PmsmSysidError(f"--diagnose-sim {params['sim_namespace']}: that is the drive's "
                             "own namespace (--namespace); the simulator must publish under "
                             "another one")
    return tuple(dict.fromkeys([*nodes, "diagnose"]))


def _check(args: argparse.Namespace) -> None:
    from ..core.errors import PmsmSysidError

    if args.duration is not None and not args.duration > 0:
        raise PmsmSysidError(f"--duration must be > 0, got {args.duration}")
    if not args.rate >= 0:
        raise PmsmSysidError(f"--rate must be >= 0, got {args.rate}")
    if args.rate != 1.0 and args.clock != "sim":
        raise PmsmSysidError("--rate applies to --clock sim only")
    if not args.wait >= 0:
        raise PmsmSysidError(f"--wait must be >= 0, got {args.wait}")
    if args.subscribers < 1:
        raise PmsmSysidError(f"--subscribers must be >= 1, got {args.subscribers}")
    if args.report is not None:
        from pathlib import Path

        if Path(args.report).exists() and not Path(args.report).is_dir():
            raise PmsmSysidError(f"--report {args.report}: exists and is not a directory")


def run(args: argparse.Namespace) -> int:
    from ..core.online.workerproc import start_server
    from ..core.physics.plant import load_plant
    from ..pipeline_nodes import WORKER_NODES, parse_nodes

    _check(args)
    nodes = parse_nodes(args.nodes)
    params = node_params(args)
    nodes = _with_diagnosis(nodes, args, params["diagnose"])
    plant = load_plant(args.plant)
    if set(nodes) & set(WORKER_NODES):  # every input checked: the workers' imports can
        start_server()  # start, beside this process's own below

    from ..app import build_pipeline
    from ..rosutil import stop_on_signals
    from .common import replace_bag_dir, write_json
    from .run_verdict import headline, verdict

    if args.record:
        replace_bag_dir(Path(args.record), args.force)  # checked at the start: ours to replace
    with build_pipeline(nodes, plant=plant, excitation=args.excitation, seed=args.seed,
                        clock=args.clock, rate=args.rate, namespace=args.namespace,
                        record=args.record, wait_s=args.wait, subscribers=args.subscribers,
                        ros_args=getattr(args, "ros_args", None),
                        identifier_params=params["identifier"],
                        sim_params=params["sim"], gfrf_params=params["gfrf"],
                        diagnose_params=params["diagnose"]) as pipe, \
            stop_on_signals(pipe.stop):
        print(f"pmsm-sysid run: running {', '.join(nodes)} (Ctrl-C to stop)", file=sys.stderr,
              flush=True)
        pipe.run(args.duration)
        stopped = pipe.stop.is_set()
        pipe.stop.clear()
        pipe.finish()
        summary = pipe.summary()
    summary["stopped_by_signal"] = stopped
    if args.record:
        summary["record"] = args.record
    summary["verdict"] = verdict(summary)
    write_json(summary, args.json)
    out = sys.stderr if args.json == "-" else sys.stdout
    print(f"pmsm-sysid run: {headline(summary)}", file=out)
    if args.report:
        print(f"pmsm-sysid run: report {_report(summary, args)}", file=out)
    return 0


def _report(summary: dict[str, Any], args: argparse.Namespace) -> Path:
    """Write the run's report (complete, or none at all); if that fails and no --json kept
    the summary, the summary is saved in the temporary directory and the error says where."""
    from ..core.errors import PmsmSysidError
    from ..report.build import report_summary
    from ..validate import atomic_dir, rescue_path
    from .common import write_json

    try:
        with atomic_dir(args.report, "--report") as tmp:
            index = Path(report_summary(summary, tmp).index)
        return Path(args.report) / index.relative_to(tmp)
    except PmsmSysidError as exc:
        if args.json not in (None, "-"):
            raise
        spare = rescue_path("pmsm-sysid-run")
        write_json(summary, str(spare))
        raise type(exc)(f"{exc}; the run summary was saved to {spare}") from exc
