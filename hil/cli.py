"""``pyrhonn hil``: replay, score and bench (registered through the
``pyrhonn.commands`` entry point; pyrhonn does not import hil).

    pyrhonn hil replay [--transport virtual|udp_multicast|socketcan] [--channel CH] [--duration S]
                       [--seed N] [--frame-loss P] [--out DIR] [--log FILE.blf] [--progress | --quiet]
    pyrhonn hil score LOG [--out DIR] [--json]
    pyrhonn hil bench --cycles N [--transport udp_multicast] [--identifier CFG --dbc DBC --trajectory FILE]

Exit codes: 0 run complete (every frame accounted for, estimates bit-exact),
1 a run that completed but is not (see the report), 2 bad input or a run that
could not happen (firmware not answering, a log that cannot be written), 130
and 143 a replay stopped by SIGINT (Ctrl-C) and SIGTERM: its ``--log`` then
holds every frame up to that moment, whole and readable, marked partial in
its sidecar (``hil score`` and ``--from-log`` refuse it; ``hil score
--partial`` scores it anyway).
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

__all__ = ["register"]


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 2:
        raise argparse.ArgumentTypeError(f"expected an integer >= 2, got {v}")
    return v


def _float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    return v


def _seconds(*, zero: bool) -> Callable[[str], float]:
    """An argparse type for a wait in seconds (hil.rig.check_seconds)."""
    def parse(text: str) -> float:
        from .rig import check_seconds

        try:
            return check_seconds("value", _float(text), zero=zero)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix("value: ")) from None
    return parse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("hil", help="hardware-in-the-loop replay of an identifier's firmware over a CAN bus "
                                   "(the LIM rig, or your exported identifier)",
                       description="Hardware-in-the-loop replay against the identifier firmware over python-can: the "
                                   "paper's real-time LIM test (section 6.3.2), or an identifier you exported "
                                   "(--identifier, --dbc) with a recorded trajectory as its plant.")
    hs = p.add_subparsers(dest="hil_command", metavar="HIL_COMMAND")
    hs.required = True

    r = hs.add_parser("replay", help="replay a scenario (the LIM's, or --identifier's trajectory) against the firmware, "
                                            "score and report it")
    _transport_args(r)
    # scenario options default to None: Scenario's own defaults apply, and --from-log can refuse them
    r.add_argument("--duration", type=_float, default=None, help="replayed seconds (default 4.0: 13,333 cycles)")
    r.add_argument("--start", type=_float, default=None, help="trajectory time of the first frame (default 0)")
    r.add_argument("--seed", type=int, default=None, help="(default 0)")
    r.add_argument("--frame-loss", type=_float, default=None, help="probability a frame is lost (default 0)")
    r.add_argument("--delay", type=_float, default=None, help="fixed transport delay in seconds (default 0)")
    r.add_argument("--encoder-resolution", type=_float, default=None,
                   help="position encoder resolution in m (default 10e-6, SENC 50; 0: none)")
    r.add_argument("--hold-start", type=_float, default=None, help="measurement hold start, s (default 1.1)")
    r.add_argument("--hold-duration", type=_float, default=None, help="measurement hold, s (default 1.0; 0: none)")
    r.add_argument("--input-start", type=_float, default=None,
                   help="when the LIM's voltages switch on, s (default 2.0, eq. 21-22 of the paper; 1.0: the "
                        "motor moves through the whole hold)")
    r.add_argument("--trajectory", type=Path, default=None, metavar="FILE.csv",
                   help="replay a recorded LIM trajectory instead of simulating the plant: a CSV with columns t, "
                        "q_m, v, lambda_a, lambda_b, i_a, i_b, u_a, u_b, sampled at the period or an integer "
                        "fraction of it (`pyrhonn hil trajectory` writes one); --start and --hold-start are on "
                        "its time axis")
    r.add_argument("--identifier", type=Path, default=None, metavar="CFG.toml",
                   help="replay another identifier instead of the LIM: the config file (float32) it was selected "
                        "or tuned into; needs --dbc and --trajectory (a CSV with t and the config's states and "
                        "inputs), whose samples go out as that DBC's Measurement frames")
    r.add_argument("--dbc", type=Path, default=None, metavar="FILE.dbc",
                   help="with --identifier: the protocol DBC pyrhonn export --dbc wrote for it")
    r.add_argument("--from-log", type=Path, default=None, metavar="RUN.blf",
                   help="replay the scenario of a recorded run (from its sidecar) and compare every estimate with "
                        "the recorded one: a regression check of a firmware build (exit 1 when any differs); "
                        "the scenario options above are then refused")
    r.add_argument("--out", type=Path, default=None, help="directory for report.json, report.txt and the PNGs")
    r.add_argument("--log", type=Path, default=None, help="record the run to FILE.blf, FILE.asc or FILE.mf4 (MDF4) (+ FILE.json)")
    r.add_argument("--json", action="store_true", help="print the JSON report instead of the table")
    _verdict_args(r, "its [scenario] table is the replay's scenario (an option above may not set a field it sets; "
                     "refused with --from-log)")
    shown = r.add_mutually_exclusive_group()
    shown.add_argument("--progress", dest="progress", action="store_const", const="always", default="auto",
                       help="show the replay's progress on stderr (cycles done, estimates back, losses) even when "
                            "stderr is not a terminal: a line every 2 s (on a terminal it is shown anyway, one "
                            "line updated every 0.5 s)")
    shown.add_argument("--quiet", dest="progress", action="store_const", const="never",
                       help="no progress line on stderr")
    r.set_defaults(func=_replay)

    t = hs.add_parser("trajectory", help="write the simulated LIM trajectory as a CSV (the --trajectory format)")
    t.add_argument("out", type=Path, metavar="OUT.csv")
    t.add_argument("--duration", type=_float, default=4.0, help="seconds (default 4.0)")
    t.add_argument("--step", type=_float, default=3e-4,
                   help="sampling step, s, dividing the rig's 0.3 ms period (default 3e-4)")
    t.add_argument("--input-start", type=_float, default=2.0,
                   help="when the LIM's voltages switch on, s (default 2.0)")
    t.set_defaults(func=_trajectory)

    s = hs.add_parser("score", help="re-score a recorded log offline")
    s.add_argument("log", type=Path)
    s.add_argument("--out", type=Path, default=None)
    s.add_argument("--json", action="store_true")
    s.add_argument("--partial", action="store_true",
                   help="score a partial log (a run stopped by SIGINT/SIGTERM or a lost bus) anyway; its unsent "
                        "cycles then count as unaccounted")
    _verdict_args(s, "a [scenario] table in it must be the log's own scenario")
    s.set_defaults(func=_score)

    b = hs.add_parser("bench", help="cyclictest-style timing of both sides at 0.3 ms")
    _transport_args(b, default="udp_multicast", bench=True)
    b.add_argument("--cycles", type=_positive_int, required=True)
    b.add_argument("--identifier", type=Path, default=None, metavar="CFG.toml",
                   help="time another identifier than the LIM (at rest): the config file (float32) it was selected "
                        "or tuned into; needs --dbc and --trajectory, as hil replay")
    b.add_argument("--dbc", type=Path, default=None, metavar="FILE.dbc",
                   help="with --identifier: the protocol DBC pyrhonn export --dbc wrote for it")
    b.add_argument("--trajectory", type=Path, default=None, metavar="FILE.csv",
                   help="with --identifier: the recording replayed from its start, covering --cycles periods "
                        "(a CSV with t and the config's states and inputs)")
    b.add_argument("--fifo", type=_fifo_priority, metavar="PRIO",
                   help="run the rig (and the firmware process it starts) under SCHED_FIFO at PRIO (1..99), "
                        "as a real-time test would; refused without root / CAP_SYS_NICE (then said so)")
    b.add_argument("--cpus", type=_cpu_pair, metavar="RIG,FIRMWARE",
                   help="pin the rig to CPU RIG and the firmware process it starts to CPU FIRMWARE (as "
                        "cyclictest -a; on a 2-CPU host: 0,1), so neither migrates nor shares a CPU")
    b.add_argument("--json", action="store_true")
    b.set_defaults(func=_bench)


def _verdict_args(p: argparse.ArgumentParser, scenario_table: str) -> None:
    p.add_argument("--scenario", type=Path, default=None, metavar="FILE.toml",
                   help="a scenario file: its [thresholds] table sets limits on the run's RMSE per state, dropout "
                        "bridging ratio, lost frames and latency percentiles, each judged pass/fail in the report "
                        f"(exit 1 when one fails); {scenario_table}")
    p.add_argument("--junit", type=Path, default=None, metavar="FILE.xml",
                   help="write the verdicts as JUnit XML, one testcase per threshold and per check of the run")
    p.add_argument("--summary", type=Path, default=None, metavar="FILE.json",
                   help="write the verdicts as a JSON summary (passed, failed, each measured value and limit)")


def _check_verdict_outputs(args) -> None:
    """--junit and --summary, before the run: in an existing folder, not a folder themselves."""
    for option, path in (("--junit", args.junit), ("--summary", args.summary)):
        if path is None:
            continue
        if path.is_dir():
            raise ValueError(f"{option}: {path} is a directory")
        if not path.parent.is_dir():
            raise ValueError(f"{option}: folder {str(path.parent)!r} of {path.name} does not exist")


def _runner_spin(args, bench: bool) -> float:
    """--runner-spin-us, defaulted: the bench busy-polls where the runner can have a CPU of its own (on one
    it would take the rig's); refused where no runner is started here to take it (it would be ignored)."""
    from .transport import RUNNER_SPIN_MAX_US, RUNNER_SPIN_US

    starts_runner = (args.transport == "udp_multicast" and args.firmware != "python") or (
        args.transport == "socketcan" and args.runner is not None)
    if not starts_runner:
        if args.runner_spin_us is not None:
            raise ValueError("--runner-spin-us: only for a rhonn_runner started here (udp_multicast, or socketcan "
                             "with --runner)")
        return RUNNER_SPIN_US
    if args.runner_spin_us is not None:
        return args.runner_spin_us
    return RUNNER_SPIN_MAX_US if bench and len(os.sched_getaffinity(0)) >= 2 else RUNNER_SPIN_US


def _transport_args(p: argparse.ArgumentParser, default: str = "udp_multicast", *, bench: bool = False) -> None:
    from .transport import FIRMWARES, RUNNER_SPIN_MAX_US, RUNNER_SPIN_US, TRANSPORTS

    p.add_argument("--transport", choices=TRANSPORTS, default=default)
    p.add_argument("--channel", default=None,
                   help="virtual: a channel name; udp_multicast: the group (default 239.74.163.2); socketcan: vcan0/can0")
    p.add_argument("--port", type=int, default=None, help="udp_multicast port (default: a fresh one per run)")
    p.add_argument("--runner", default=None,
                   help="the rhonn_runner to start: socketcan (default: one already runs) and udp_multicast "
                        "(default: built from the source tree; where there is none, the Python node serves)")
    p.add_argument("--firmware", choices=FIRMWARES, default=None,
                   help="udp_multicast: the firmware process, runner (rhonn_runner, the C firmware: --runner, else "
                        "built from the source tree with cc on first use) or python (hil.firmware_node, the same "
                        "logic through cffi, where there is no C compiler); default runner")
    p.add_argument("--runner-spin-us", type=_float, default=None, metavar="US",
                   help="a rhonn_runner started here (udp_multicast, socketcan with --runner): how long it "
                        "busy-polls either side of each expected Measurement instead of sleeping, "
                        f"0..{RUNNER_SPIN_MAX_US:g} (default "
                        + (f"{RUNNER_SPIN_MAX_US:g} on a host with two or more CPUs: it never sleeps, as a "
                           f"real-time task that owns its CPU, and costs that CPU; else {RUNNER_SPIN_US:g})"
                           if bench else f"{RUNNER_SPIN_US:g})"))
    p.add_argument("--timeout", type=_seconds(zero=False), default=1.0,
                   help="seconds to wait for the firmware (default 1)")
    p.add_argument("--drain", type=_seconds(zero=True), default=0.3,
                   help="after the replay, read estimates until none has come for this many seconds "
                        "(at most 20 times as long; default 0.3)")


def timing_note(transport: str) -> str:
    vm = bool(os.environ.get("PYRHONN_VM_OUT")) or _dmi().startswith(("qemu", "standard pc"))
    where = {"virtual": "in-process virtual bus (firmware in a Python thread: timing includes GIL hand-overs)",
             "udp_multicast": "udp_multicast between two processes on this host (no CAN controller)",
             "socketcan": "SocketCAN"}[transport]
    note = f"timing measured over {where}"
    if vm:
        note += "; inside an emulated VM timing is NOT meaningful (functional results are)"
    return note


def _dmi() -> str:
    try:
        return Path("/sys/class/dmi/id/product_name").read_text().strip().lower()
    except OSError:
        return ""


#: replay options that make the scenario: argparse dest -> Scenario field
SCENARIO_OPTIONS = {"duration": "duration", "start": "start", "seed": "seed", "frame_loss": "frame_loss",
                    "delay": "transport_delay", "encoder_resolution": "encoder_resolution",
                    "hold_start": "hold_start", "hold_duration": "hold_duration", "input_start": "input_start",
                    "trajectory": "trajectory", "identifier": "identifier", "dbc": "dbc"}


def _scenario(args, recorded=None, file=None):
    """The replay's Scenario: ``recorded``'s (the --from-log run) or the one the options and the
    scenario ``file``'s [scenario] table make."""
    from .scenario import Scenario, identifier_defaults

    given = [dest for dest in SCENARIO_OPTIONS if getattr(args, dest) is not None]
    if recorded is not None:
        if given:
            raise ValueError(f"--from-log: replays the recorded run's own scenario; drop "
                             f"{', '.join('--' + d.replace('_', '-') for d in given)}")
        if file is not None and file.scenario:
            raise ValueError(f"--from-log: replays the recorded run's own scenario; {file.path} has a [scenario] "
                             "table (keep only its [thresholds])")
        return recorded.scenario
    paths = ("trajectory", "identifier", "dbc")
    kw = {SCENARIO_OPTIONS[dest]: getattr(args, dest) for dest in given if dest not in paths}
    if args.trajectory is not None:
        if args.input_start is not None:
            raise ValueError("--input-start: applies to the simulated plant, not to a --trajectory file")
    kw.update({dest: str(getattr(args, dest)) for dest in paths if getattr(args, dest) is not None})
    from pyrhonn.cli.options import options_named

    with options_named(**{field: "--" + dest.replace("_", "-") for dest, field in SCENARIO_OPTIONS.items()}):
        if file is not None and file.scenario:
            return file.make_scenario(**kw)
        return Scenario(**identifier_defaults(kw))


def _trajectory(args) -> int:
    from pyrhonn.plants import lim
    from pyrhonn.plants.trajectory import check_length

    from .scenario import Scenario
    from .trajectory import samples_per_period, write_trajectory

    try:
        samples_per_period(args.step, Scenario().period)
    except ValueError as exc:
        raise ValueError(f"--step: {exc}") from None
    if not 0 < args.duration <= 3600:
        raise ValueError(f"--duration: expected seconds in (0, 3600], got {args.duration!r}")
    if not 0 <= args.input_start < float("inf"):
        raise ValueError(f"--input-start: expected finite seconds >= 0, got {args.input_start!r}")
    K = int(round(args.duration / args.step))
    if K < 2:
        raise ValueError(f"--duration: must cover at least 2 steps of {args.step:g} s, got {args.duration!r}")
    check_length("--duration", K * args.step, args.step, "--step")  # before anything of that size is allocated
    traj = lim.simulate(dt=args.step, horizon=K * args.step, inputs=lim.LimInput(start=args.input_start), holds=())
    write_trajectory(args.out, traj.t, traj.X, traj.U)
    print(f"wrote {traj.t.size} samples (t = 0..{traj.t[-1]:g} s, step {args.step:g} s) of the simulated LIM "
          f"(PROPOSED parameters, voltages from {args.input_start:g} s) to {args.out}")
    return 0


def _emit(report: dict, args, note: str | None, file=None) -> int:
    from . import report as rep
    from .verdicts import Thresholds, evaluate, failed, write_outputs

    verdicts = evaluate(report, file.thresholds if file is not None else Thresholds())
    report["verdicts"] = [v.to_dict() for v in verdicts]
    report["_verdicts"] = (verdicts, None if file is None else str(file.path))
    if args.json:
        print(rep.to_json(report))
    else:
        print(rep.table(report, timing_note=note), end="")
    if getattr(args, "out", None) is not None:
        paths = rep.write(report, args.out, timing_note=note)
        print(f"wrote {', '.join(str(p) for p in paths)}", file=sys.stderr)
    suite = f"pyrhonn hil {args.hil_command}" + ("" if file is None else f" {file.path.stem}")
    paths = write_outputs(report, verdicts, None if file is None else str(file.path), junit=args.junit,
                          summary_path=args.summary, suite=suite)
    if paths:
        print(f"wrote {', '.join(str(p) for p in paths)}", file=sys.stderr)
    return 1 if failed(verdicts) else 0


def _check_log_path(path: Path | None) -> None:
    """--log, before the run (the log and its sidecar are written after it;
    its .blf/.asc name is checked first thing in _replay): not a directory,
    in an existing folder this process can write in."""
    from .rig import sidecar

    if path is None:
        return
    for p in (path, sidecar(path)):
        if p.is_dir():
            raise ValueError(f"--log: {p} is a directory")
        if p.exists() and not os.access(p, os.W_OK):
            raise ValueError(f"--log: {p} is not writable")
    folder = path.parent
    if not folder.is_dir():
        raise ValueError(f"--log: folder {str(folder)!r} of {path.name} does not exist")
    try:  # a real write: permission bits alone do not say it (as root, or on a read-only mount)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".pyrhonn-hil-", suffix=".tmp"):
            pass
    except OSError as exc:
        raise ValueError(f"--log: cannot write in folder {str(folder)!r} ({exc.strerror or exc})") from None


def _check_out(out: Path | None) -> None:
    """--out, before the run: created if needed and proved writable (as pyrhonn reproduce's --out)."""
    from pyrhonn.reproduce import check_output_dir

    if out is not None:
        check_output_dir(out)


def _check_transport_options(args) -> None:
    """Refuse what the chosen transport would silently ignore (--runner-spin-us: :func:`_runner_spin`)."""
    if args.port is not None and args.transport != "udp_multicast":
        raise ValueError(f"--port: only for udp_multicast; the {args.transport} bus has no port")
    if args.transport == "virtual":
        if args.runner is not None:
            raise ValueError("--runner: the virtual bus's firmware is a thread of this process, no rhonn_runner is "
                             "started; --runner is for udp_multicast and socketcan")
        if args.firmware is not None:
            raise ValueError("--firmware: the virtual bus's firmware is a thread of this process; --firmware "
                             "chooses the firmware process of udp_multicast")
    elif args.transport == "socketcan" and args.firmware is not None:
        raise ValueError("--firmware: only for udp_multicast; over socketcan the firmware is rhonn_runner (--runner "
                         "starts one, else one must be running already)")


def _note_fallback(side: dict | None) -> None:
    if side and side.get("fallback"):
        print(f"note: {side['fallback']}", file=sys.stderr)


def _raise_interrupted(signum: int, _frame: object) -> None:
    from .rig import Interrupted

    raise Interrupted(signum)


@contextmanager
def _stop_on_sigterm() -> Iterator[None]:
    """SIGTERM raises :class:`hil.rig.Interrupted` (as SIGINT raises KeyboardInterrupt), so a
    terminated replay ends as a Ctrl-C'd one does: its frames so far in a partial log."""
    before = signal.signal(signal.SIGTERM, _raise_interrupted)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, before)


@contextmanager
def _signals_held() -> Iterator[list[int]]:
    """SIGINT and SIGTERM are held (recorded in the list, not acted on) for the block: a log being
    written is finished first. kill -9 cannot be held; the log's temporary file then protects it."""
    held: list[int] = []
    before = {s: signal.signal(s, lambda signum, _f: held.append(signum)) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield held
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)


def _record(rec, path: Path, what: str) -> list[int]:
    """Write ``rec`` to the log ``path`` with SIGINT/SIGTERM held; the signals that came meanwhile."""
    from .rig import write_log

    with _signals_held() as held:
        write_log(rec, path)
    print(f"recorded {len(rec.events)} frames{what} to {path} (+ {path.name}.json)", file=sys.stderr)
    return held


def _signal_exit(signum: int) -> int:
    """The conventional exit code of a command stopped by ``signum``: 130 for SIGINT, 143 for SIGTERM."""
    return 128 + signum


def _replay(args) -> int:
    from .progress import progress_for
    from .rig import BusLost, Interrupted, LogWriteError, Recording, check_log_name, read_log
    from .score import compare_runs, score
    from .transport import run_replay

    _check_transport_options(args)
    spin = _runner_spin(args, bench=False)
    if args.log is not None:  # a typo: before reading anything
        check_log_name(args.log, "--log")
    file = _read_scenario_file(args)
    recorded = read_log(args.from_log) if args.from_log is not None else None
    sc = _scenario(args, recorded, file)
    _check_scored(args, file, sc)
    if recorded is not None and args.log is not None and args.log.resolve() == args.from_log.resolve():
        raise ValueError("--log: would overwrite the --from-log run it is compared with; choose another file")
    _check_out(args.out)  # first: --log may name a file in the --out folder this creates
    _check_log_path(args.log)
    _check_verdict_outputs(args)
    sc.build()  # the frames before anything is sent (cached for the run): a scenario the DBC cannot carry ends here
    keeps = f"; Ctrl-C stops it and keeps the frames so far in {args.log}" if args.log is not None else ""
    print(f"pyrhonn hil replay: {sc.cycles} cycles over {args.transport}{keeps}", file=sys.stderr, flush=True)
    progress = progress_for(args.progress, sc.cycles)
    try:
        with _stop_on_sigterm():
            try:
                rec = run_replay(sc, args.transport, args.channel, port=args.port, runner=args.runner,
                                 firmware=args.firmware or True, runner_spin_us=spin,
                                 reply_timeout=args.timeout, drain=args.drain, progress=progress,
                                 sample_drops=True)
            finally:
                if progress is not None:
                    progress.close()
    except BusLost as exc:
        if args.log is not None:  # keep what was recorded up to the loss (a partial log)
            _record(exc.recording, args.log, " (up to the loss; marked partial)")
        raise
    except KeyboardInterrupt as exc:  # SIGINT, or SIGTERM as Interrupted
        signum = getattr(exc, "signum", signal.SIGINT)
        name = signal.Signals(signum).name
        partial = exc.recording if isinstance(exc, Interrupted) else None
        if partial is None:  # before the rig started: --log still ends as this run's log, an empty partial one
            partial = Recording(scenario=sc, meta={"transport": args.transport, "channel": args.channel,
                                               "wall_time_ns": time.time_ns(),
                                               "partial": f"interrupted by {name} before the first frame"})
        if args.log is not None:
            _record(partial, args.log, f" (up to the {name}; marked partial)")
        print(f"pyrhonn hil replay: interrupted by {name}", file=sys.stderr)
        return _signal_exit(signum)
    log_error = None
    if args.log is not None:  # first: a Ctrl-C during the scoring still leaves the whole run's log
        try:
            held = _record(rec, args.log, "")
        except LogWriteError as exc:  # reported after the report, which is complete without the log
            log_error, held = exc, []
        if held:
            print(f"pyrhonn hil replay: interrupted by {signal.Signals(held[0]).name} after the run; the log is "
                  "complete", file=sys.stderr)
            return _signal_exit(held[0])
    report = score(rec, reference=sc.reference_config())
    if recorded is not None:
        report["regression"] = compare_runs(score(recorded), report, str(args.from_log))
    report["firmware_side"] = rec.meta.get("firmware_side")
    _note_fallback(report["firmware_side"])
    code = _emit(report, args, timing_note(args.transport), file)
    if log_error is not None:
        raise log_error  # an OSError: pyrhonn's main reports it, exit 2
    return code


def _score(args) -> int:
    from .rig import partial_reason, read_log, sidecar
    from .score import score

    try:
        rec = read_log(args.log, partial=args.partial)
    except ValueError as exc:
        if args.log.is_file() and not sidecar(args.log).is_file():  # a recording, not a hil replay's log
            raise ValueError(f"{exc}. hil score needs the sidecar hil replay --log writes: the scenario it "
                             "replayed is the truth it scores against. A recording without one has none; to "
                             f"identify the plant from its signals: pyrhonn identify --can-log {args.log} --dbc "
                             "FILE --config CFG (the config's [bus] table or --signal name each signal)") from None
        raise
    file = _read_scenario_file(args)
    if file is not None:
        file.check_recorded(rec.scenario)
    _check_scored(args, file, rec.scenario)
    _check_out(args.out)
    _check_verdict_outputs(args)
    report = score(rec, reference=rec.scenario.reference_config())
    why = partial_reason(rec)
    if why:
        report["partial"] = why
    return _emit(report, args, f"re-scored from {args.log}", file)


def _read_scenario_file(args):
    """The --scenario file (hil.scenario_file); its per-state limits are checked by :func:`_check_scored`."""
    from .scenario_file import read_scenario_file

    if args.scenario is None:
        return None
    return read_scenario_file(args.scenario)


def _check_scored(args, file, sc) -> None:
    """The --scenario file's per-state limits against the states the scenario's report scores."""
    from .score import scored_states

    if file is None:
        return
    try:
        file.thresholds.check_states(tuple(name for name, _j, _unit in scored_states(sc)))
    except ValueError as exc:
        raise ValueError(f"{args.scenario}: {exc}") from None


def _fifo_priority(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a priority 1..99, got {text!r}") from None
    if not 1 <= value <= 99:
        raise argparse.ArgumentTypeError(f"expected a priority 1..99, got {value}")
    return value


def _cpu_pair(text: str) -> tuple[int, int]:
    from .transport import parse_cpu_pair

    try:
        cpus = parse_cpu_pair(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    allowed = sorted(os.sched_getaffinity(0))
    bad = [c for c in cpus if c not in allowed]
    if bad:
        raise argparse.ArgumentTypeError(f"CPU {bad[0]} is not one this process may use {allowed}")
    return cpus


def _bench_scenario(cycles: int, args=None):
    """The bench's Scenario of ``cycles`` periods: the LIM at rest, or with ``args.identifier`` that
    identifier's recording (``args.dbc``, ``args.trajectory``) from its start, built; a ValueError naming
    --cycles when it is longer than a scenario (or the recording) may be, or the option that is missing
    or refused."""
    from pyrhonn.cli.options import options_named

    from .scenario import Scenario, identifier_defaults

    paths = {name: getattr(args, name, None) for name in ("identifier", "dbc", "trajectory")}
    if paths["identifier"] is None:
        given = next((name for name, v in paths.items() if v is not None), None)
        if given is not None:
            raise ValueError(f"--{given}: only with --identifier (the LIM's bench runs it at rest, with no recording)")
    try:
        if paths["identifier"] is None:
            return Scenario.at_rest(cycles)
        duration = cycles * Scenario().period
    except (ValueError, OverflowError) as exc:  # OverflowError: an int beyond float64 times the period
        shown = str(cycles) if len(str(cycles)) <= 24 else f"a {len(str(cycles))}-digit number of"
        raise ValueError(f"--cycles: {shown} cycles of {Scenario().period * 1e3:g} ms are longer than a run may be "
                         f"({exc})") from None
    fields_ = {name: str(v) for name, v in paths.items() if v is not None}
    with options_named(identifier="--identifier", dbc="--dbc", trajectory="--trajectory", duration="--cycles"):
        sc = Scenario(**identifier_defaults({**fields_, "duration": duration}))
        sc.build()   # a recording shorter than --cycles periods ends here, before anything starts
    return sc


def _bench(args) -> int:
    from . import report as rep
    from .host import StealMeter, steal_line
    from .score import score
    from .transport import run_replay, use_fifo

    _check_transport_options(args)
    if args.cpus is not None and args.transport == "virtual":
        raise ValueError("--cpus: the virtual bus's firmware is a thread of the rig's process; use "
                         "udp_multicast or socketcan")
    sc = _bench_scenario(args.cycles, args)
    spin = _runner_spin(args, bench=True)
    policy = use_fifo(args.fifo)
    firmware_cpu = None
    if args.cpus is not None:
        firmware_cpu = args.cpus[1]
        policy += f", rig on CPU {args.cpus[0]}, firmware on CPU {args.cpus[1]}"

    cpus_before = os.sched_getaffinity(0)
    if args.cpus is not None:
        os.sched_setaffinity(0, {args.cpus[0]})
    steal = StealMeter()
    steal.start()
    try:
        rec = run_replay(sc, args.transport, args.channel, port=args.port, runner=args.runner,
                         firmware=args.firmware or True, runner_spin_us=spin,
                         reply_timeout=args.timeout, drain=args.drain, firmware_cpu=firmware_cpu)
    finally:
        os.sched_setaffinity(0, cpus_before)
    r = score(rec, reference=sc.reference_config() if sc.identifier else None)
    r["host_steal"] = steal.stop()
    side = rec.meta.get("firmware_side") or {}
    if "spin_us" in side.get("stats", {}):  # a runner started here
        policy += f", runner busy-polls {spin:g} us either side of each frame"
    _note_fallback(side)
    note = timing_note(args.transport)
    if args.json:
        r["firmware_side"] = side
        r["policy"] = policy
        print(rep.to_json(r))
        return 0

    def row(name: str, st: dict | None) -> str:
        if not st or not st.get("n"):
            return f"{name:<34} (not available)"
        return (f"{name:<34} n {st['n']:>7}  min {st['min']:8.1f}  avg {st['avg']:8.1f}  p99 {st['p99']:8.1f}  "
                f"p99.9 {st['p99.9']:8.1f}  max {st.get('max', st.get('max_abs', 0.0)):9.1f}")

    lat = r["latency_us"]
    what = "" if not sc.identifier else f" of {sc.identifier}"
    print(f"pyrhonn hil bench: {args.cycles} cycles{what} at 0.3 ms over {args.transport} ({r['channel']}), "
          f"{policy}, all in us")
    print(row("rig: wake-up lateness (deadline)", r["rig_lateness_us"]))
    print(row("rig: period jitter |dt - T|", {**r["rig_period_jitter_us"],
                                                 "max": r["rig_period_jitter_us"].get("max_abs", 0.0)}))
    print(row("round trip send -> estimate", lat))
    print(row("rig: pick-up of received frames", r.get("rig_pickup_us")))
    print(row("firmware: Measurement interval", side.get("arrival_interval_us")))
    print(row("firmware: handling per frame", side.get("handling_us")))
    if r.get("firmware"):
        print(f"{'firmware: StepTimeMax (Diagnostics)':<34} {rep.step_time(r['firmware'])}"
              f"  overruns {r['firmware']['overruns']}")
    if lat.get("n"):
        at = "at the rig's socket (kernel receive timestamp)" if lat.get("stamp") == "kernel" else "received"
        print(f"estimates within one period, {at}: {100 * lat['within_period']:.3f} %  "
              f"(answered {r['frames']['answered']} of {r['frames']['sent']}, late {r['frames']['late']})")
        if "within_period_picked_up" in lat:
            print(f"estimates within one period, picked up by the rig process: "
                  f"{100 * lat['within_period_picked_up']:.3f} %")
    print(steal_line(r["host_steal"], args.cpus))
    print(f"note: {note}")
    return 0 if r["frames"]["accounted"] else 1
