"""What writing whole files costs: ``Identifier.save`` (a temporary file,
fsynced, renamed over the target, the folder fsynced: pyrhonn.atomic)
against the plain write it replaced (``np.savez`` into the target opened
for writing), and ``hil.rig.write_log`` (the same, plus the SHA-256 in the
sidecar) against python-can's BLF writer straight into the target, in the
same run and the same folder.

Every figure is the best of several repeats (the least disturbed by other
load); the comparison is their ratio.

    python bench/bench_writes.py              # in a temporary folder
    python bench/bench_writes.py --dir DIR    # on the disk that holds DIR
    python bench/bench_writes.py --results    # also write bench/results/writes.json (the docs quote it)
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

from pyrhonn import Identifier, presets


def best(fn: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


class _PlainWrites:
    """pyrhonn.atomic's ``replacing`` as it was before: the target truncated and written in place."""

    @staticmethod
    def replacing(path: Path, mode: str = "wb"):
        return open(path, mode)


def bench_save(folder: Path, repeats: int) -> tuple[float, float]:
    import pyrhonn.statefile as statefile

    ident = Identifier(presets.example1("float64"))
    rng = np.random.default_rng(0)
    ident.run(rng.standard_normal((200, 4)), rng.standard_normal((200, 1)))
    path = folder / "state.npz"
    ident.save(path)
    whole = best(lambda: ident.save(path), repeats)
    atomic = statefile.atomic
    statefile.atomic = _PlainWrites  # type: ignore[assignment]
    try:
        plain = best(lambda: ident.save(path), repeats)
    finally:
        statefile.atomic = atomic
    return plain, whole


def bench_log(folder: Path, repeats: int, duration: float) -> tuple[int, float, float]:
    import can

    from hil.rig import write_log
    from hil.scenario import Scenario
    from hil.transport import run_replay

    rec = run_replay(Scenario(duration=duration), "virtual")
    path = folder / "run.blf"

    def plain() -> None:
        writer = can.BLFWriter(path)
        for ts, d, m in rec.events:
            m.timestamp = ts
            m.is_rx = d == "rx"
            writer.on_message_received(m)
        writer.stop()

    return len(rec.events), best(plain, repeats), best(lambda: write_log(rec, path), repeats)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dir", type=Path, default=None, help="folder to write in (default: a temporary one)")
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--duration", type=float, default=4.0, help="seconds of the replayed run (default 4)")
    ap.add_argument("--results", action="store_true", help="also write the figures to bench/results/writes.json")
    args = ap.parse_args()
    if args.repeats < 1 or not args.duration > 0:
        ap.error("--repeats: at least 1; --duration: above 0")
    if args.results:  # imported now: it notes the load average at the start of the run
        from results_file import save  # noqa: E402 - beside this script
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        folder = Path(tmp)
        plain, whole = bench_save(folder, args.repeats)
        print(f"Identifier.save (example1): plain {plain * 1e3:.2f} ms, whole "
              f"{whole * 1e3:.2f} ms, x{whole / plain:.2f}")
        save_ms = {"plain_ms": plain * 1e3, "whole_ms": whole * 1e3, "ratio": whole / plain}
        frames, plain, whole = bench_log(folder, max(3, args.repeats // 4), args.duration)
        print(f"hil log ({frames} frames, BLF): plain {plain * 1e3:.0f} ms, whole with SHA-256 "
              f"{whole * 1e3:.0f} ms, x{whole / plain:.2f}")
    if args.results:
        save("writes", {"settings": {"repeats": args.repeats, "log_repeats": max(3, args.repeats // 4),
                                     "duration_s": args.duration, "folder": "given" if args.dir else "temporary"},
                        "identifier_save": save_ms,
                        "hil_log": {"frames": frames, "plain_ms": plain * 1e3, "whole_ms": whole * 1e3,
                                    "ratio": whole / plain}})


if __name__ == "__main__":
    main()
