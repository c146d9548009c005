"""One identifier shared by threads: calls are serialised, nothing is lost;
separate identifiers run in parallel and stay bit-identical to a serial run."""
from __future__ import annotations

import sys
import threading

import numpy as np
import pytest

from pyrhonn import Identifier
from pyrhonn.configfile import load_shipped

from strategies import trajectory


def test_two_threads_running_one_identifier_lose_no_step_and_raise_nothing() -> None:
    config = load_shipped("example1").config
    X, U, _ = trajectory(1, 40000, 4, 1)
    ident = Identifier(config)
    errors: list[BaseException] = []
    rounds = 10

    def worker(rows: slice) -> None:
        try:
            for _ in range(rounds):
                ident.run(X[rows], U[rows])
                ident.step(X[0], U[0])
                ident.health(0)
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=worker, args=(slice(0, 20000),)),
               threading.Thread(target=worker, args=(slice(20000, 40000),))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert ident.steps == 2 * rounds * 20001
    assert sum(ident.health(i).updates for i in range(4)) == 4 * (2 * rounds * 20001 - 1)


def test_separate_identifiers_in_threads_equal_a_serial_run_bit_for_bit() -> None:
    config = load_shipped("example1").config
    X, U, _ = trajectory(2, 20000, 4, 1)
    serial = Identifier(config).run(X, U)
    results: list[np.ndarray] = [np.empty(0)] * 2

    def worker(k: int) -> None:
        results[k] = Identifier(config).run(X, U)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for r in results:
        np.testing.assert_array_equal(r, serial)


@pytest.mark.parametrize("lanes", [False, True], ids=["rhonn_step", "lanes"])
def test_threads_stepping_one_identifier_each_get_their_own_steps_predictions(lanes: bool) -> None:
    # Each thread steps its own samples. Afterwards one serial replay must
    # explain both threads' predictions: at each step, the next prediction
    # of one of the threads, bit for bit, in each thread's own order.
    config = load_shipped("example1").config
    per_thread = 2000
    X, U, _ = trajectory(3, 2 * per_thread, 4, 1)
    samples = [(X[k::2], U[k::2]) for k in (0, 1)]  # every sample differs: no thread's predictions settle
    ident = Identifier(config)
    ident._wide = lanes  # steps lent to the vector lanes, or in rhonn_step
    results: list[list[np.ndarray]] = [[], []]
    errors: list[BaseException] = []

    def worker(k: int) -> None:
        step, (Xk, Uk) = ident.step, samples[k]
        try:
            results[k] = [step(Xk[i], Uk[i]) for i in range(per_thread)]
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # the threads take turns as often as they can
    try:
        threads = [threading.Thread(target=worker, args=(k,)) for k in range(2)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        sys.setswitchinterval(interval)
    assert errors == []

    replay = Identifier(config)
    replay._wide = False  # its whole state in the struct, which the replay puts back
    state = replay._ffi.buffer(replay._net)
    taken = [0, 0]
    for _ in range(2 * per_thread):
        before = bytes(state)
        for k in (0, 1):
            i = taken[k]
            if i < per_thread and replay.step(samples[k][0][i], samples[k][1][i]).tobytes() == results[k][i].tobytes():
                taken[k] += 1
                break
            replay._ffi.memmove(replay._net, before, len(before))
        else:
            raise AssertionError(f"no thread's next prediction follows step {sum(taken)}")
    assert taken == [per_thread, per_thread]
