"""save/load keeps the full filter state: a loaded identifier continues bit
for bit; corrupt, foreign or tampered files are rejected by name."""
from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from pyrhonn import Factor, Identifier, IdentifierConfig, terms
from pyrhonn.statefile import FORMAT, VERSION

from killing import kill_while_writing
from strategies import trajectory


def config(dtype: str) -> IdentifierConfig:
    return IdentifierConfig.uniform(
        terms.first_order(3, 1) + terms.pairwise_products(3) + terms.delayed_taps(1, [1, 4], raw=True),
        n_states=3, n_inputs=1, dtype=dtype, p0=50.0, q=1e-3, r=0.5, beta=0.7)


@pytest.mark.parametrize("dtype", ["float64", "float32"])
@pytest.mark.parametrize("learning", [True, False])
def test_loaded_identifier_continues_bit_for_bit(tmp_path: Path, dtype: str, learning: bool) -> None:
    X, U, valid = trajectory(3, 600, 3, 1, 0.1, dtype)
    a = Identifier(config(dtype))
    a.run(X[:300], U[:300], valid[:300])
    a.learning = learning
    a.save(tmp_path / "state.npz")
    b = Identifier.load(tmp_path / "state.npz")
    assert b.config == a.config and b.steps == a.steps and b.learning == learning
    np.testing.assert_array_equal(b.prediction, a.prediction)
    np.testing.assert_array_equal(a.run(X[300:], U[300:], valid[300:]), b.run(X[300:], U[300:], valid[300:]))


def test_state_saved_before_the_first_step_loads_as_fresh(tmp_path: Path) -> None:
    X, U, valid = trajectory(4, 100, 3, 1)
    a = Identifier(config("float64"))
    a.save(tmp_path / "s.npz")
    b = Identifier.load(tmp_path / "s.npz")
    np.testing.assert_array_equal(a.run(X, U), b.run(X, U))


def test_delayed_inputs_are_saved_and_continue_bit_for_bit(tmp_path: Path) -> None:
    cfg = IdentifierConfig.uniform(terms.first_order(2, 1) + ((Factor.u(0, delay=3),), (Factor.u(0, 2, delay=1),)),
                                   n_states=2, n_inputs=1, p0=10.0, q=1e-3, r=0.5)
    X, U, valid = trajectory(6, 200, 2, 1, 0.1)
    a = Identifier(cfg)
    a.run(X[:100], U[:100], valid[:100])
    a.save(tmp_path / "s.npz")
    b = Identifier.load(tmp_path / "s.npz")
    np.testing.assert_array_equal(a.run(X[100:], U[100:], valid[100:]), b.run(X[100:], U[100:], valid[100:]))


def test_a_version_1_state_file_still_loads_and_continues(tmp_path: Path) -> None:
    """Version 1 stored D+1 history rows, no input history (inputs had no delay)
    and no measured-run counts (read as every state measured, as here)."""
    X, U, valid = trajectory(7, 300, 3, 1, 0.0)
    a = Identifier(config("float64"))
    a.run(X[:150], U[:150])
    a.save(tmp_path / "v2.npz")

    def to_v1(m):
        header_with(version=1)(m)
        m["history"] = np.vstack((m["history"], m["history"][-1:]))  # the extra, unread oldest row
        del m["input_history"], m["valid_run"]
    b = Identifier.load(rewrite(tmp_path / "v2.npz", tmp_path / "v1.npz", to_v1))
    np.testing.assert_array_equal(a.run(X[150:], U[150:], valid[150:]), b.run(X[150:], U[150:], valid[150:]))


def saved(tmp_path: Path) -> Path:
    X, U, _ = trajectory(5, 80, 3, 1)
    ident = Identifier(config("float64"))
    ident.run(X, U)
    path = tmp_path / "good.npz"
    ident.save(path)
    return path


def rewrite(src: Path, dst: Path, change) -> Path:
    with np.load(src, allow_pickle=False) as z:
        members = {k: z[k] for k in z.files}
    change(members)
    with open(dst, "wb") as fh:
        np.savez(fh, **members)
    return dst


def header_with(**kw):
    def change(m):
        h = json.loads(str(m["header"][()]))
        h.update(kw)
        m["header"] = np.array(json.dumps(h))
    return change


def _indefinite_packed(p: np.ndarray) -> np.ndarray:
    """A packed covariance of the same size with a positive diagonal and an eigenvalue of about -3."""
    L = int((np.sqrt(8 * p.size + 1) - 1) / 2)
    P = np.eye(L)
    P[0, 1] = P[1, 0] = 4.0
    return P[np.triu_indices(L)].astype(p.dtype)


@pytest.mark.parametrize("change,message", [
    (header_with(format="other-tool"), r"header\.format"),
    (header_with(version=VERSION + 1), rf"header\.version: version {VERSION + 1} is newer"),
    (header_with(version="1"), r"header\.version"),
    (header_with(dtype="float32"), r"header\.dtype"),
    (header_with(steps=-1), r"header\.steps"),
    (header_with(learning="yes"), r"header\.learning"),
    (header_with(config={"n_states": 3}), r"header\.config"),
    (lambda m: m.pop("w_1"), r"w_1: missing"),
    (lambda m: m.update(w_0=m["w_0"][:-1]), r"w_0: expected shape"),
    (lambda m: m.update(p_2=m["p_2"].astype(np.float32)), r"p_2: expected dtype float64"),
    (lambda m: m.update(xhat=np.array([0.0, np.nan, 0.0])), r"xhat: contains non-finite"),
    (lambda m: m.update(history=m["history"][:1]), r"history: expected shape"),
    (lambda m: m.update(p_0=-np.abs(m["p_0"])), r"p_0: covariance diagonal"),
    (lambda m: m.update(extra=np.zeros(1)), r"archive: unexpected members"),
    (lambda m: m.update(header=np.array([1, 2])), r"header: expected a JSON object"),
    (lambda m: m.update(header=np.array("[" * 100_000 + "]" * 100_000)), r"header: unreadable \(JSON nested too deeply"),
    (header_with(config={"n_states": 10**400}), r"header\.config"),
    (lambda m: m.update(p_1=_indefinite_packed(m["p_1"])), r"p_1: covariance not positive semi-definite"),
])
def test_tampered_state_file_is_rejected_by_member(tmp_path: Path, change, message: str) -> None:
    bad = rewrite(saved(tmp_path), tmp_path / "bad.npz", change)
    with pytest.raises(ValueError, match=message):
        Identifier.load(bad)


def test_corrupt_and_foreign_files_are_rejected(tmp_path: Path) -> None:
    good = saved(tmp_path)
    data = good.read_bytes()
    (tmp_path / "truncated.npz").write_bytes(data[: len(data) // 2])
    (tmp_path / "text.npz").write_text("hello, not a state file\n")
    (tmp_path / "empty.npz").write_bytes(b"")
    np.save(tmp_path / "array.npy", np.zeros(3))
    with zipfile.ZipFile(tmp_path / "other.zip", "w") as zf:
        zf.writestr("readme.txt", "a zip from someone else")
    flipped = bytearray(data)
    flipped[len(flipped) // 3] ^= 0xFF
    (tmp_path / "flipped.npz").write_bytes(bytes(flipped))
    for name in ["truncated.npz", "text.npz", "empty.npz", "array.npy", "other.zip", "flipped.npz", "missing.npz"]:
        with pytest.raises(ValueError, match=str(tmp_path / name).replace(".", r"\.")):
            Identifier.load(tmp_path / name)


def test_format_is_documented_and_stable() -> None:
    assert FORMAT == "pyrhonn-state" and VERSION == 2


def _filter_state(ident: Identifier) -> tuple[bytes, ...]:
    n = ident.config.n_states
    return (ident.steps.to_bytes(8, "little"), ident.prediction.tobytes(),
            *(ident.get_weights(i).tobytes() for i in range(n)),
            *(ident.get_covariance(i).tobytes() for i in range(n)))


def test_a_save_killed_at_any_moment_leaves_the_old_or_the_new_state_file(tmp_path: Path) -> None:
    """100 times: a child process saves two states in turn over one file and is
    killed (SIGKILL) at a random moment; the file always loads, as one of them."""
    X, U, valid = trajectory(6, 200, 3, 1)
    old, new = Identifier(config("float64")), Identifier(config("float64"))
    old.run(X[:60], U[:60], valid[:60])
    new.run(X, U, valid)
    states = {_filter_state(old): "old", _filter_state(new): "new"}
    assert len(states) == 2
    path = tmp_path / "state.npz"
    old.save(path)
    rng = np.random.default_rng(2)
    seen = set()
    for _ in range(100):
        kill_while_writing([lambda: new.save(path), lambda: old.save(path)], rng, max_delay=0.02)
        seen.add(states[_filter_state(Identifier.load(path))])  # KeyError: neither state
    assert seen == {"old", "new"}
    # what a kill can leave beside it is a hidden temporary file, never something that looks like an output
    assert all(p.name == "state.npz" or p.name.startswith(".state.npz.tmp-") for p in tmp_path.iterdir())
