"""hil.host: the hypervisor's steal time around a timing run."""
from __future__ import annotations

import os

import pytest

from hil.host import StealMeter, steal_line, steal_ticks

STAT = """cpu  1368036 0 212796 1633480 11959 0 15354 {total} 0 0
cpu0 684018 0 106398 816740 5979 0 7677 {s0} 0 0
cpu1 684018 0 106398 816740 5980 0 7677 {s1} 0 0
intr 123 4 5
ctxt 99
"""


def _stat(s0: int, s1: int) -> str:
    return STAT.format(total=s0 + s1, s0=s0, s1=s1)


def test_steal_is_the_eighth_value_of_each_cpu_line_and_the_aggregate_line_is_skipped() -> None:
    assert steal_ticks(_stat(7, 12)) == {0: 7, 1: 12}
    assert steal_ticks("intr 1 2\n") == {}


def test_a_cpu_line_without_a_steal_column_is_refused_by_name() -> None:
    with pytest.raises(ValueError, match="cpu0 has no steal column"):
        steal_ticks("cpu0 1 2 3 4 5 6 7\n")


def test_the_meter_reports_the_steal_between_start_and_stop_in_ms(tmp_path) -> None:
    path = tmp_path / "stat"
    path.write_text(_stat(100, 200))
    meter = StealMeter(path)
    meter.start()
    path.write_text(_stat(103, 200))
    got = meter.stop()
    tick_ms = 1000.0 / os.sysconf("SC_CLK_TCK")
    assert got["available"] and got["ms"] == {0: 3 * tick_ms, 1: 0.0} and got["total_ms"] == 3 * tick_ms
    line = steal_line(got, (0, 1))
    assert line.startswith(f"host: steal time CPU0 {3 * tick_ms:.0f} ms, CPU1 0 ms") and "hypervisor" in line
    assert "none counted" in steal_line({**got, "ms": {0: 0.0, 1: 0.0}, "total_ms": 0.0})
    assert "CPU1" not in steal_line(got, (0,))


@pytest.mark.parametrize("content", [None, "cpu0 1 2\n"])
def test_an_unreadable_or_malformed_stat_reports_unavailable_with_the_reason(tmp_path, content) -> None:
    path = tmp_path / "stat"
    if content is not None:
        path.write_text(content)
    meter = StealMeter(path)
    meter.start()
    got = meter.stop()
    assert got["available"] is False and str(path) in got["why"]
    assert steal_line(got).startswith("host: steal time not available (")
    assert StealMeter(path).stop()["why"]  # never started: still a report, not an exception


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="Linux /proc")
def test_this_hosts_proc_stat_is_read() -> None:
    meter = StealMeter()
    meter.start()
    got = meter.stop()
    assert got["available"] and set(got["ms"]) and all(v >= 0 for v in got["ms"].values())
