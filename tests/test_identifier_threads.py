"""One identifier shared by threads: calls are serialised, nothing is lost;
separate identifiers run in parallel and stay bit-identical to a serial run."""
from __future__ import annotations

import threading

import numpy as np

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
