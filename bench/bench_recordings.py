"""Identifying from recordings: lossy bus logs in every format, and a long recording end to end.

1. The firmware's Measurement frames of the LIM example (``--frames``, default 10,001 at 0.3 ms)
   with ``--loss`` (default 0.5 %) of them lost at random, written as candump, BLF, ASC and MDF4 bus
   logs and as the CSV of the same samples with a ``lost`` column. Each is identified by
   ``pyrhonn identify`` in its own process; the bench checks that the predictions are the same from
   every file and that every lost frame is counted, and reports each run's wall time and peak memory.
2. A long recording (``--long``, default 10^6 samples) as a candump, BLF, ASC and MDF4 bus log and as
   CSV (``--long-formats``): ``identify``'s end-to-end time and peak memory against the C core's own
   time on the same samples (``Identifier.run`` over the segments), as a same-run ratio. A bus log is
   read a chunk of frames at a time (:mod:`pyrhonn.buslogstream`), so its peak memory does not grow
   with its length: ``--longer F`` (default 4) also identifies the candump log F times over (its copies
   one after the other in time, written a block of lines at a time) and reports its time, ratio and
   peak beside the first. ``signal-mf4`` is the same samples as a signal MDF4 of named channels
   (the states in one channel group, without the lost samples, the inputs in another), streamed a
   block of records at a time (:class:`pyrhonn.mdfsignals.SignalMdfStream`), its ratio against the core's
   time in the same run. ``csv-ahead`` identifies the CSV with a free run from its middle and
   ``--steps-ahead`` (``--ahead``, default 5) predictions, streamed as every mode is, and once more
   with the record held whole (the reference: its predictions.csv must be the same bytes): the time,
   ratio to the core and peak memory of each.
3. With ``--huge N`` (12,000,000: an hour at 0.3 ms), a CSV of N samples (``--loss`` lost, written
   straight from the arrays, about 1.9 GB in ``--huge-dir``, deleted afterwards) through ``identify``
   (plots included), then the same samples without the lost ones through ``select --search fixed``
   (the default candidate space; a record longer than ``--max-fit-rows`` fits on windows of it and
   is validated on every row): the time and peak memory of each.

    python bench/bench_recordings.py [--frames 10001] [--loss 0.005] [--long 1000000]
        [--long-formats log,blf,asc,mf4,csv,signal-mf4,csv-ahead] [--ahead 5] [--longer 4]
        [--huge 12000000 --huge-dir /tmp] [--results [--merge]]

``--results`` writes the figures to bench/results/recordings.json (bench/results_file.py); with
``--merge`` the figures this run does not make (``--frames 0`` skips part 1) are kept from the file,
and the long recording's formats it runs replace theirs there.

Needs python-can, cantools and asammdf (pyrhonn's dependencies).
"""
from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

import can
import results_file
from pyrhonn import Identifier, firmware
from pyrhonn.configfile import load_shipped, shipped_text
from pyrhonn.gaps import segments_of
from pyrhonn.plants import lim

PERIOD = 3e-4
T0 = 1_700_000_000.0
STATES = ("q_m", "v", "lambda_a", "lambda_b", "i_a", "i_b")
BUS = "\n[bus]\nsample_period = 0.0003\nclock = \"Measurement\"\n\n[bus.signals]\n" + "".join(
    f"{n} = \"Measurement.{s}\"\n" for n, s in zip(STATES + ("u_a", "u_b"), firmware.STATE_SIGNALS
                                                    + firmware.INPUT_SIGNALS)) + "\n[bus.valid]\n" + "".join(
    f"{n} = \"Measurement.{s}\"\n" for n, s in zip(STATES, firmware.VALID_SIGNALS))
# peak memory: the process's own high-water mark (VmHWM). Not getrusage's ru_maxrss, which a child
# started by fork and exec inherits from its parent: this bench, holding 10^6 frames, would be counted.
RUN = ("import json, sys, time\n"
       "from pyrhonn.cli import main\n"
       "t = time.perf_counter()\n"
       "code = main(sys.argv[1:])\n"
       "hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM:')][0].split()[1]\n"
       "print(json.dumps({'code': code, 'seconds': time.perf_counter() - t, 'peak_mib': int(hwm) / 1024}))\n")


def _samples(n: int, synthetic: bool) -> tuple[np.ndarray, np.ndarray]:
    """(X, U): the LIM example from just before its inputs switch on, or smooth signals in the DBC's
    ranges for a long recording (the simulation of 10^6 samples would dominate the bench)."""
    if not synthetic:
        traj = lim.simulate(dt=PERIOD, horizon=2.0 + n * PERIOD + 0.01)
        k0 = int(round(2.0 / PERIOD))
        return traj.X[k0:k0 + n].copy(), traj.U[k0:k0 + n].copy()
    return _samples_at(0, n)


def _samples_at(a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
    """Samples a..b-1 of the smooth synthetic signals (in the DBC's ranges)."""
    k = np.arange(a, b)[:, None]
    X = np.hstack([np.sin(k * w) * a for w, a in ((1e-3, 1.0), (7e-4, 2.0), (3e-3, 1.0), (2e-3, 1.0), (5e-3, 20.0),
                                                  (4e-3, 20.0))])
    U = np.hstack([np.sin(k * 6.1e-3) * 150.0, np.cos(k * 3.7e-3) * 150.0])
    return X, U


def _frames(X: np.ndarray, U: np.ndarray, lost: set[int]) -> list[can.Message]:
    out = []
    for k in range(X.shape[0]):
        if k in lost:
            continue
        m = firmware.measurement_message(k, X[k], U[k])
        m.timestamp = round(T0 + k * PERIOD, 6)
        out.append(m)
    return out


def _candump_line(m: can.Message) -> str:
    return f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}##1{bytes(m.data).hex().upper()}\n"


def _write(frames: list[can.Message], path: Path) -> None:
    if path.suffix == ".log":
        with path.open("w") as fh:
            for m in frames:
                fh.write(_candump_line(m))
        return
    with can.Logger(str(path)) as logger:
        for m in frames:
            logger.on_message_received(m)


def _csv(frames: list[can.Message], n: int, path: Path) -> None:
    meas = firmware.database().get_message_by_name("Measurement")
    by_k = {int(round((m.timestamp - T0) / PERIOD)): m for m in frames}
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([*STATES, "u_a", "u_b", "lost"])
        for k in range(n):
            if k not in by_k:
                w.writerow([""] * 8 + ["1"])
                continue
            d = meas.decode(bytes(by_k[k].data), decode_choices=False)
            w.writerow([repr(float(d[s])) for s in firmware.STATE_SIGNALS + firmware.INPUT_SIGNALS] + ["0"])


#: the record held whole instead of streamed (identify's reference path)
WHOLE = "import pyrhonn.cli.identify as identify\nidentify._WHOLE_RECORD = True\n"


def _identify(argv: list[str], cwd: Path, whole: bool = False) -> dict[str, float]:
    """``pyrhonn identify`` in its own process (run in ``cwd``, away from a source tree without the built
    core): its exit code, wall time and peak memory; ``whole``: with the record held whole."""
    done = subprocess.run([sys.executable, "-c", (WHOLE if whole else "") + RUN, *argv], capture_output=True,
                          text=True, cwd=cwd)
    if done.returncode != 0:
        raise SystemExit(f"identify crashed: {' '.join(argv)}\n{done.stderr}")
    result = json.loads(done.stdout.strip().splitlines()[-1])
    if result["code"] != 0:
        raise SystemExit(f"identify failed: {' '.join(argv)}\n{done.stderr}")
    return result


def _csv_direct(X: np.ndarray, U: np.ndarray, lost: np.ndarray, path: Path, rows: int = 1 << 16) -> None:
    """The CSV of the samples (as float32 values, as the frames carry them) with a ``lost`` column, written
    straight from the arrays a block of rows at a time (a 12 M-sample file without 12 M frames)."""
    with path.open("w", newline="") as fh:
        fh.write(",".join([*STATES, "u_a", "u_b", "lost"]) + "\n")
        for a in range(0, X.shape[0], rows):
            b = min(a + rows, X.shape[0])
            cols = [repr(np.hstack([X[a:b], U[a:b]])[:, j].astype(np.float32).astype(np.float64).tolist())[1:-1]
                    .split(", ") for j in range(8)]
            gone = lost[a:b].tolist()
            fh.write("".join(",,,,,,,,1\n" if g else ",".join(r) + ",0\n" for r, g in zip(zip(*cols), gone)))


def _repeated(log: Path, times: int, shift: float, path: Path) -> None:
    """The candump ``log`` ``times`` over, each copy ``shift`` s after the one before: a log longer than the
    frames this bench can hold, written a block of lines at a time."""
    with path.open("w") as out:
        for r in range(times):
            with log.open() as src:
                for block in iter(lambda: src.readlines(1 << 22), []):
                    out.write("".join(f"({float(line[1:line.index(')')]) + r * shift:.6f}{line[line.index(')'):]}"
                                      for line in block))


def _longer(log: Path, times: int, X: np.ndarray, U: np.ndarray, lost: np.ndarray, d: Path) -> dict[str, float]:
    """``identify`` on the candump ``log`` of the samples ``X``, ``U`` (``lost`` ones left out) repeated
    ``times`` over; the core's own time on the same samples."""
    path = d / "longer.log"
    _repeated(log, times, X.shape[0] * PERIOD, path)
    n = times * X.shape[0]
    core = _core_seconds(np.tile(X, (times, 1)), np.tile(U, (times, 1)), np.tile(lost, times))
    r = _identify(["identify", "--can-log", str(path), "--dbc", str(d / "rhonn_id.dbc"), "--config",
                   str(d / "lim.toml"), "--out", str(d / "out-longer"), "--no-plots"], d)
    found = {"samples": n, "lost": times * int(lost.sum()), "file_mib": path.stat().st_size / 2**20,
             "core_seconds": core, "seconds": r["seconds"], "peak_mib": r["peak_mib"], "ratio": r["seconds"] / core}
    metrics = json.loads((d / "out-longer" / "metrics.json").read_text())
    assert metrics["samples"] == n and metrics["gaps"]["lost_samples"] == found["lost"], metrics["gaps"]
    path.unlink()
    (d / "out-longer" / "predictions.csv").unlink()
    (d / "out-longer" / "samples.csv").unlink()
    return found


def _huge(n: int, loss: float, folder: Path, d: Path, seed: int) -> dict[str, float]:
    """``identify`` (plots included) on a CSV of ``n`` samples written to ``folder`` (deleted after)."""
    rng = np.random.default_rng(seed)
    path = folder / f"pyrhonn-bench-huge-{n}.csv"
    try:
        block = 1 << 20
        with path.open("w", newline="") as fh:
            fh.write(",".join([*STATES, "u_a", "u_b", "lost"]) + "\n")
        for a in range(0, n, block):  # written in blocks: the samples of 12 M rows are not held
            b = min(a + block, n)
            X, U = _samples_at(a, b)
            lost = rng.random(b - a) < loss
            lost[0] = lost[0] and a > 0
            lost[-1] = lost[-1] and b < n
            part = path.with_suffix(".part")
            _csv_direct(X, U, lost, part)
            with path.open("a") as out, part.open() as src:
                next(src)
                for chunk in iter(lambda: src.read(1 << 22), ""):
                    out.write(chunk)
            part.unlink()
        size = path.stat().st_size
        r = _identify(["identify", str(path), "--config", str(d / "lim.toml"), "--out", str(d / "out-huge")], d)
        metrics = json.loads((d / "out-huge" / "metrics.json").read_text())
        (d / "out-huge" / "predictions.csv").unlink()
        found: dict[str, Any] = {"samples": n, "file_mib": size / 2**20, "seconds": r["seconds"], "peak_mib": r["peak_mib"],
                 "lost": metrics["gaps"]["lost_samples"] if "gaps" in metrics else 0}
        print(f"3. {n:,} samples ({found['lost']:,} lost) as a {found['file_mib']:,.0f} MiB CSV: identify "
              f"{r['seconds']:.0f} s, peak {r['peak_mib']:.0f} MiB (plots included)")
        # select has no lost samples to read: the same signals without the lost column
        clean = folder / f"pyrhonn-bench-huge-{n}-select.csv"
        with path.open() as src, clean.open("w") as out:
            for read in iter(lambda: src.readlines(1 << 22), []):
                out.writelines(line.rsplit(",", 1)[0] + "\n" for line in read if not line.endswith(",1\n"))
        path.unlink()
        # select's own budget (100,000 rows) on an hour's record; a quarter of a short one, so that a small run
        # goes through the same windows
        budget = min(100_000, max(n // 4, 1_000))
        sel = _identify(["select", str(clean), "--states", ",".join(STATES), "--inputs", "u_a,u_b", "--search",
                         "fixed", "--max-fit-rows", str(budget), "--out", str(d / "huge-select.toml"), "--json", str(d / "huge-select.json")], d)
        rows = json.loads((d / "huge-select.json").read_text())["long_records"][0]
        clean.unlink()
        print(f"   select --search fixed: {sel['seconds']:.0f} s, peak {sel['peak_mib']:.0f} MiB; fitted on "
              f"{len(rows['windows'])} windows, {rows['budget']:,} rows, validated on all {rows['rows']:,}")
        return {**found, "select": {"seconds": sel["seconds"], "peak_mib": sel["peak_mib"], "rows": rows["rows"],
                                    "budget": rows["budget"], "windows": len(rows["windows"]),
                                    "settings": "--search fixed (the default candidate space), "
                                                f"--max-fit-rows {budget}"}}
    finally:
        for leftover in (path, path.with_suffix(".part"), folder / f"pyrhonn-bench-huge-{n}-select.csv"):
            leftover.unlink(missing_ok=True)


def _recorded(frames: list[can.Message], n: int, path: Path, d: Path) -> dict[str, float]:
    """``frames`` written as ``path`` (its suffix says the format), then identified into ``out-<stem>``."""
    if path.suffix == ".csv":
        _csv(frames, n, path)
        source = [str(path)]
    else:
        _write(frames, path)
        source = ["--can-log", str(path), "--dbc", str(d / "rhonn_id.dbc")]
    return _identify(["identify", *source, "--config", str(d / "lim.toml"), "--out", str(d / f"out-{path.stem}"),
                      "--no-plots"], d)


def _signal_mdf(X: np.ndarray, U: np.ndarray, lost: np.ndarray, path: Path, d: Path) -> dict[str, float]:
    """The samples as a signal MDF4 (float32 values, as the frames carry them): the states' channels in one
    group without the lost samples, the inputs' in another with every sample; then identified into
    ``out-<stem>`` (the default period: the median interval of the first state's channel)."""
    import asammdf

    t = PERIOD * np.arange(X.shape[0])
    kept = ~lost
    mdf = asammdf.MDF(version="4.10")
    mdf.append([asammdf.Signal(X[kept, j].astype(np.float32), t[kept], name=name) for j, name in enumerate(STATES)],
               comment="states")
    mdf.append([asammdf.Signal(U[:, j].astype(np.float32), t, name=name) for j, name in enumerate(("u_a", "u_b"))],
               comment="inputs")
    mdf.save(str(path), overwrite=True)
    mdf.close()
    return _identify(["identify", str(path), "--config", str(d / "lim.toml"), "--out", str(d / f"out-{path.stem}"),
                      "--no-plots"], d)


def _ahead(frames: list[can.Message], n: int, steps: int, core: float, d: Path) -> dict[str, object]:
    """The long CSV identified with ``--free-run-from n/2 --steps-ahead steps``, streamed and held whole (the
    same predictions.csv): the seconds, ratio to the core's time and peak memory of each."""
    path = d / "long-ahead.csv"
    _csv(frames, n, path)
    K = n // 2
    runs: dict[str, dict[str, float]] = {}
    for how in ("streamed", "whole"):
        out = d / f"out-ahead-{how}"
        r = _identify(["identify", str(path), "--config", str(d / "lim.toml"), "--out", str(out), "--no-plots",
                       "--free-run-from", str(K), "--steps-ahead", str(steps)], d, whole=how == "whole")
        runs[how] = {"seconds": r["seconds"], "peak_mib": r["peak_mib"], "ratio": r["seconds"] / core}
        print(f"   csv, free run from {K:,} and {steps} steps ahead, {how}: identify {r['seconds']:6.1f} s "
              f"({r['seconds'] / core:5.1f} x the core), peak {r['peak_mib']:6.0f} MiB")
    same = (d / "out-ahead-streamed" / "predictions.csv").read_bytes() == \
        (d / "out-ahead-whole" / "predictions.csv").read_bytes()
    print(f"   predictions.csv the same streamed and held whole: {same}")
    if not same:
        raise SystemExit(1)
    size = path.stat().st_size / 2**20
    path.unlink()
    for how in runs:
        (d / f"out-ahead-{how}" / "predictions.csv").unlink()
    return {"file_mib": size, "free_run_from": K, "steps": steps, "core_seconds": core, "same_predictions": same,
            **runs["streamed"], "whole": runs["whole"],
            "peak_vs_whole": runs["streamed"]["peak_mib"] / runs["whole"]["peak_mib"]}


def _predictions(out: Path) -> list[dict[str, str]]:
    with (out / "predictions.csv").open(newline="") as fh:
        return [{k: v for k, v in row.items() if k.endswith(("_hat", "_err"))} for row in csv.DictReader(fh)]


def _core_seconds(X: np.ndarray, U: np.ndarray, lost: np.ndarray) -> float:
    """The C core's own time: Identifier.run over the segments (float32), best of three."""
    cfg = load_shipped("firmware-lim").config
    segs = segments_of(lost)
    Xf, Uf = X.astype(np.float32), U.astype(np.float32)
    valid = np.ones(X.shape, dtype=bool)
    best = np.inf
    for _ in range(3):
        ident = Identifier(cfg)
        t = time.perf_counter()
        for i, (a, b) in enumerate(segs.bounds):
            if i:
                ident.restart()
            ident.run(Xf[a:b], Uf[a:b], valid[a:b])
        best = min(best, time.perf_counter() - t)
    return best


def _lossy(n: int, lost: set[int], loss: float, d: Path) -> dict[str, object]:
    """Part 1: the lossy frames in every format, identified; their predictions the same."""
    X, U = _samples(n, synthetic=False)
    frames = _frames(X, U, lost)
    print(f"1. {n:,} Measurement frames, {len(lost)} lost at random ({loss:.1%})")
    runs: dict[str, dict[str, float]] = {}
    for suffix in ("log", "blf", "asc", "mf4", "csv"):
        path = d / f"lossy-{suffix}.{suffix}"
        runs[suffix] = _recorded(frames, n, path, d)
        gaps = json.loads((d / f"out-{path.stem}" / "metrics.json").read_text())["gaps"]
        assert gaps["lost_samples"] == len(lost), (suffix, gaps["lost_samples"])
        print(f"   {suffix:4s} {path.stat().st_size / 2**20:7.2f} MiB: {runs[suffix]['seconds']:6.2f} s, peak "
              f"{runs[suffix]['peak_mib']:6.0f} MiB; {gaps['lost_samples']} lost in {gaps['gaps']} gaps, "
              f"{gaps['restarts']} restarts")
    want = _predictions(d / "out-lossy-csv")
    same = all(_predictions(d / f"out-lossy-{s}") == want for s in ("log", "blf", "asc", "mf4"))
    print(f"   predictions equal across candump, BLF, ASC, MDF4 and CSV: {same}")
    if not same:
        raise SystemExit(1)
    return {"frames": n, "lost": len(lost), "loss": loss, "same_predictions": same, "formats": runs}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=10_001)
    ap.add_argument("--loss", type=float, default=0.005)
    ap.add_argument("--long", type=int, default=1_000_000)
    ap.add_argument("--long-formats", default="log,blf,asc,mf4,csv,signal-mf4,csv-ahead",
                    help="formats of the long recording (log, blf, asc, mf4 bus log, csv, signal-mf4; csv-ahead: "
                         "the CSV with a free run and --ahead steps ahead)")
    ap.add_argument("--ahead", type=int, default=5, help="csv-ahead's --steps-ahead (default 5)")
    ap.add_argument("--longer", type=int, default=4,
                    help="also the long candump log this many times over (0: not), for the peak memory's growth")
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--out", type=Path, default=None, help="keep the files here (default: a temporary folder)")
    ap.add_argument("--huge", type=int, default=0, help="also identify a CSV of this many samples (e.g. 12000000)")
    ap.add_argument("--huge-dir", type=Path, default=Path(tempfile.gettempdir()),
                    help="where the --huge CSV is written (and deleted afterwards)")
    ap.add_argument("--results", action="store_true", help="write bench/results/recordings.json")
    ap.add_argument("--merge", action="store_true",
                    help="with --results: keep the file's figures that this run does not make")
    args = ap.parse_args()
    figures: dict[str, object] = {}
    earlier: dict[str, object] = {}
    if args.merge:
        earlier = json.loads((results_file.FOLDER / "recordings.json").read_text())
        figures = dict(earlier["figures"])  # type: ignore[call-overload]
    with tempfile.TemporaryDirectory() as tmp:
        d = args.out or Path(tmp)
        d.mkdir(parents=True, exist_ok=True)
        (d / "lim.toml").write_text(shipped_text("firmware-lim") + BUS)
        (d / "rhonn_id.dbc").write_text(firmware.database().as_dbc_string())
        rng = np.random.default_rng(args.seed)
        n = args.frames
        lost = {int(k) for k in np.flatnonzero(rng.random(n) < args.loss) if 0 < k < n - 1}
        if n:
            figures["lossy"] = _lossy(n, lost, args.loss, d)


        N = args.long
        if N:
            lost_big = {int(k) for k in np.flatnonzero(rng.random(N) < args.loss) if 0 < k < N - 1}
            Xb, Ub = _samples(N, synthetic=True)
            big = _frames(Xb, Ub, lost_big)
            lost_mask = np.zeros(N, dtype=bool)
            lost_mask[sorted(lost_big)] = True
            core = _core_seconds(Xb, Ub, lost_mask)
            print(f"2. {N:,} samples, {len(lost_big):,} lost; the C core alone (Identifier.run over the segments, "
                  f"float32): {core:.2f} s")
            long: dict[str, object] = {"samples": N, "lost": len(lost_big), "core_seconds": core, "plots": False}
            before = figures.get("long")
            if args.merge and isinstance(before, dict):
                alone = set(args.long_formats.split(",")) <= {"signal-mf4", "csv-ahead"}
                long = {**before, **({} if alone else long)}
            for suffix in args.long_formats.split(","):
                if suffix == "csv-ahead":
                    long["csv_ahead"] = _ahead(big, N, args.ahead, core, d)
                    continue
                if suffix == "signal-mf4":
                    path = d / "long-signal.mf4"
                    r = _signal_mdf(Xb, Ub, lost_mask, path, d)
                    print(f"   signal MDF4 {path.stat().st_size / 2**20:7.1f} MiB: identify {r['seconds']:6.1f} s "
                          f"({r['seconds'] / core:5.1f} x the core), peak {r['peak_mib']:6.0f} MiB")
                    long["signal_mf4"] = {"file_mib": path.stat().st_size / 2**20, "seconds": r["seconds"],
                                          "peak_mib": r["peak_mib"], "core_seconds": core, "ratio": r["seconds"] / core}
                    path.unlink()
                    for name in ("predictions.csv", "samples.csv"):
                        (d / f"out-{path.stem}" / name).unlink(missing_ok=True)
                    continue
                path = d / f"long-{suffix}.{suffix}"
                r = _recorded(big, N, path, d)
                print(f"   {suffix:4s} {path.stat().st_size / 2**20:7.1f} MiB: identify {r['seconds']:6.1f} s "
                      f"({r['seconds'] / core:5.1f} x the core), peak {r['peak_mib']:6.0f} MiB")
                long[suffix] = {"file_mib": path.stat().st_size / 2**20, "seconds": r["seconds"],
                                "peak_mib": r["peak_mib"], "ratio": r["seconds"] / core}
                if not (suffix == "log" and args.longer):
                    path.unlink()
                for name in ("predictions.csv", "samples.csv"):
                    (d / f"out-{path.stem}" / name).unlink(missing_ok=True)
            del big
            if args.longer and "log" in long:
                longer = _longer(d / "long-log.log", args.longer, Xb, Ub, lost_mask, d)
                (d / "long-log.log").unlink()
                growth = longer["peak_mib"] / long["log"]["peak_mib"] if "log" in long else None  # type: ignore[index]
                long["longer"] = {**longer, "times": args.longer, "peak_vs_log": growth}
                print(f"   log x{args.longer}: {longer['samples']:,} samples, {longer['file_mib']:.0f} MiB: identify "
                      f"{longer['seconds']:.1f} s ({longer['ratio']:.1f} x the core), peak {longer['peak_mib']:.0f} MiB"
                      + (f" ({growth:.2f} x the 1x log's)" if growth else ""))
            figures["long"] = long
        if args.results:  # saved now, and again with part 3 if it runs
            results_file.save("recordings", figures)
        if args.huge:
            figures["huge"] = _huge(args.huge, args.loss, args.huge_dir, d, args.seed)
    if args.results:
        path = results_file.save("recordings", figures)
        if args.merge:
            _merged(path, earlier, [f.replace("-", "_") for f in args.long_formats.split(",")] if args.long else [])


def _merged(path: Path, earlier: dict[str, object], formats: list[str]) -> None:
    """The results file as it was (its run's date, command, machine and load) with this run's figures, each
    long-recording format this run measured carrying this run's own date, command and load (``run``)."""
    from pyrhonn import atomic

    record = json.loads(path.read_text())
    run = {key: record[key] for key in ("date", "command", "load")}
    for fmt in formats:
        if fmt in record["figures"].get("long", {}):
            record["figures"]["long"][fmt]["run"] = run
    merged = {**earlier, "figures": record["figures"]}
    atomic.write_text(path, json.dumps(merged, indent=1, allow_nan=False, sort_keys=False) + "\n")


if __name__ == "__main__":
    main()
