"""A cut MDF4 file read up to its last complete record: a repaired copy that asammdf opens.

An MDF4 file is a graph of blocks linked by absolute byte offsets. A file cut short (a recorder that
lost power, a copy that stopped) keeps the blocks that end before the cut. What that leaves depends
on where the writer put its blocks:

- **Channel metadata first, data appended** (a streaming recorder, the layout an unfinalised
  ``UnFinMF`` file has): the identification, header, data group, channel group and channel blocks
  are whole; the data blocks end at the cut. Every complete record before the cut is read.
- **Data first, channel metadata last** (asammdf's ``MDF.save``, and so python-can's ``can.Logger``
  / ``MF4Writer``, which saves through asammdf when it stops): the data blocks come right after the
  header and every data group, channel group and channel block sits in the last few percent of the
  file. A cut anywhere before them leaves no channel: nothing can be read. A cut among them keeps the
  groups whose blocks are all before it (their data is whole).

:func:`plan_cut` walks the block headers (nothing is allocated or decompressed from a size the file
declares before it is checked against the file's size) and finds, per data group, the complete
records: a data block (``##DT``) cut short is kept up to its last whole record, a compressed block
(``##DZ``) cut short is dropped with every block after it, a data list (``##DL``) is rewritten to
the blocks kept, and the channel group's cycle count is set to the records kept. A data group whose
own blocks (its channel group, channels, names, conversions) are not all before the cut is unlinked
and named lost, as is one whose records of several channel groups interleave (unsorted) when its
data is cut. :func:`repaired_copy` writes the file with those patches to a temporary file: asammdf
reads it as any MDF4, the same decoding a whole file gets. The original is never written.
"""
from __future__ import annotations

import os
import shutil
import struct
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

__all__ = ["MdfCut", "plan_cut", "repaired_copy"]

_HEAD = struct.Struct("<4s4xQQ")  # id, reserved, block length, number of links
_DZ = struct.Struct("<2sBxIQQ")  # original block type, zip type, reserved, zip parameter, original length, length
_DL = struct.Struct("<B3xI")  # flags, reserved, number of blocks
_CG = struct.Struct("<QQHH4xII")  # record id, cycle count, flags, path separator, reserved, data bytes, inval bytes
#: block types that hold data (followed as data, not as channel metadata)
_DATA = {b"DT", b"DZ", b"DL", b"HL", b"SD", b"RD", b"DV", b"DI", b"RV", b"RI", b"LD"}
#: the most blocks followed in one file (a long bus log has one data block per few MiB)
MAX_BLOCKS = 1 << 20
#: the most bytes deflate gives per compressed byte (a block declaring more is damaged)
MAX_INFLATE = 1032
#: channel names quoted per group in what a cut file misses
NAMES_QUOTED = 3


class _Damaged(Exception):
    """A block that is not where a link says (not a cut: the file is damaged)."""


@dataclass(frozen=True)
class Group:
    """A data group of a cut file: its number (from 1), the first names of its channels, its records
    kept and the records its channel group declared (``lost``: its blocks are past the cut)."""

    number: int
    names: tuple[str, ...]
    kept: int
    declared: int
    lost: str | None = None


@dataclass(frozen=True)
class MdfCut:
    """What a cut MDF4 keeps: ``patches`` (byte offset, bytes) that make its whole part a valid MDF4,
    and its ``groups``, kept and lost."""

    size: int
    patches: tuple[tuple[int, bytes], ...]
    groups: tuple[Group, ...]

    def read(self) -> str:
        """What is read, then what is lost, in words (after the cut's own description)."""
        read, lost = [], []
        for g in self.groups:
            if g.lost is None and g.kept == g.declared == 0:
                continue  # an empty channel group (a bus log's error frames, say): nothing to read, nothing lost
            names = ", ".join(g.names[:NAMES_QUOTED]) + (" ..." if len(g.names) > NAMES_QUOTED else "")
            label = f"channel group {g.number}" + (f" ({names})" if names else "")
            if g.lost is not None:
                lost.append(f"{label} lost ({g.lost})")
            elif g.kept == 0:
                lost.append(f"{label}: no complete record before the cut")
            elif g.kept < g.declared:
                read.append(f"the first {g.kept:,} of its {g.declared:,} records of {label}")
            else:
                read.append(f"{g.kept:,} records of {label}" + ("" if g.declared == g.kept else
                                                                f" (its channel group declares {g.declared:,})"))
        return "read " + "; ".join(read + lost)


class _File:
    def __init__(self, fh: BinaryIO, size: int) -> None:
        self.fh, self.size, self.visited = fh, size, 0

    def head(self, at: int) -> tuple[bytes, int, tuple[int, ...]] | None:
        """A block's type, length and links; None when its header or links reach past the end."""
        self.visited += 1  # a block's header is read at most a few times over
        if self.visited > 4 * MAX_BLOCKS:
            raise _Damaged(f"more than {MAX_BLOCKS:,} linked blocks")
        if at < 64:
            raise _Damaged(f"a link to byte {at:,}, inside the identification block")
        if at + _HEAD.size > self.size:
            return None
        self.fh.seek(at)
        ident, length, links = _HEAD.unpack(self.fh.read(_HEAD.size))
        if ident[:2] != b"##" or length < _HEAD.size + 8 * links:
            raise _Damaged(f"no valid block at byte {at:,} (a damaged link or block header)")
        if at + _HEAD.size + 8 * links > self.size:
            return None
        return ident[2:], length, struct.unpack(f"<{links}Q", self.fh.read(8 * links))

    def whole(self, at: int, length: int) -> bool:
        return at + length <= self.size

    def body(self, at: int, length: int, links: int, count: int) -> bytes:
        """``count`` bytes of a whole block's data section (fewer if the block is shorter)."""
        start = at + _HEAD.size + 8 * links
        self.fh.seek(start)
        return self.fh.read(max(0, min(count, at + length - start)))

    def tree_whole(self, at: int, follow_data: bool) -> bool:
        """Whether the block at ``at`` and every block it links (data blocks too when ``follow_data``;
        never another data group) end inside the file."""
        todo, seen = [at], set()
        while todo:
            here = todo.pop()
            if here in seen:
                continue
            seen.add(here)
            got = self.head(here)
            if got is None or not self.whole(here, got[1]):
                return False
            kind, _, links = got
            if kind == b"DG":
                continue
            for link in links:
                if link and link not in seen:
                    if not follow_data and self._kind(link) in _DATA:
                        if not self.tree_whole(link, True):
                            return False
                        continue
                    todo.append(link)
        return True

    def _kind(self, at: int) -> bytes:
        got = self.head(at)
        return b"" if got is None else got[0]

    def text(self, at: int) -> str:
        got = self.head(at) if at else None
        if got is None or got[0] != b"TX" or not self.whole(at, got[1]):
            return ""
        raw = self.body(at, got[1], len(got[2]), 256)
        return raw.split(b"\0", 1)[0].decode("utf-8", errors="replace")


def _exactly(raw: bytes, size: int, at: int) -> bytes:
    """``raw``, the first ``size`` bytes of the data section of the block at ``at``; a damaged block if shorter."""
    if len(raw) < size:
        raise _Damaged(f"the block at byte {at:,} is shorter than its kind is (a damaged block)")
    return raw


def _link_at(at: int, index: int) -> int:
    """The byte offset of link ``index`` of the block at ``at``."""
    return at + _HEAD.size + 8 * index


def _u64(value: int) -> bytes:
    return struct.pack("<Q", value)


def _leaves(f: _File, link: int, parent: int, listed: bool = False
            ) -> tuple[list[tuple[int, int | None, int]], list[tuple[int, bytes]]]:
    """The data blocks of a data group in order, as (block, its data list or None, index in that list),
    up to the first one past the cut; with the patches that unlink what follows a data list that is
    itself past the cut (``parent``: the byte offset of the data group's data link; ``listed``: linked from
    a header list, which links data lists only)."""
    got = f.head(link)
    if got is None or (got[0] in (b"DL", b"HL") and not f.whole(link, got[1])):
        return [], [(parent, _u64(0))]
    kind, _, links = got
    if listed and kind != b"DL":
        raise _Damaged(f"a header list links a '{kind.decode('latin-1')}' block at byte {link:,}, not a data list")
    if kind == b"HL":
        return _leaves(f, links[0], _link_at(link, 0), listed=True) if links and links[0] else ([], [])
    if kind != b"DL":
        return [(link, None, 0)], []
    leaves: list[tuple[int, int | None, int]] = []
    dl, seen = link, set()
    while dl and dl not in seen:
        seen.add(dl)
        got = f.head(dl)
        if got is None or got[0] != b"DL" or not f.whole(dl, got[1]):
            return leaves, [(parent, _u64(0))]
        leaves += [(leaf, dl, i) for i, leaf in enumerate(got[2][1:]) if leaf]
        parent, dl = _link_at(dl, 0), got[2][0]
    return leaves, []


def _rewrite_dl(f: _File, dl: int, keep: int) -> bytes:
    """The data list at ``dl`` (whole in the file) with only its first ``keep`` blocks and no next list (not
    longer than it was)."""
    got = f.head(dl)
    if got is None:
        raise _Damaged(f"no data list at byte {dl:,}")
    kind, length, links = got
    n = len(links) - 1
    flags, _ = _DL.unpack(_exactly(f.body(dl, length, len(links), _DL.size), _DL.size, dl))
    rest = f.body(dl, length, len(links), length)[_DL.size:]
    arrays = []  # the equal length (one value) or the offsets (one per block), then per flag bit 1-3 N values
    pos = 0
    if flags & 1:
        arrays.append(rest[:8])
        pos = 8
    else:
        arrays.append(rest[:8 * keep])
        pos = 8 * n
    for bit in (2, 4, 8):
        if flags & bit:
            arrays.append(rest[pos:pos + 8 * keep])
            pos += 8 * n
    data = _DL.pack(flags, keep) + b"".join(arrays)
    body = struct.pack(f"<{keep + 1}Q", 0, *links[1:keep + 1]) + data
    return _HEAD.pack(b"##" + kind, _HEAD.size + len(body), keep + 1) + body


def _group_data(f: _File, dg: int, dg_links: tuple[int, ...], record: int
                ) -> tuple[int, list[tuple[int, bytes]]] | str:
    """The complete records of a sorted data group's data and the patches that keep only them; or why
    none can be kept."""
    parent = _link_at(dg, 2)
    if not dg_links[2]:
        return 0, []
    leaves, patches = _leaves(f, dg_links[2], parent)
    total, kept, clipped = 0, 0, None  # bytes of the blocks kept, blocks kept, (block, bytes) of a cut DT
    for leaf, _, _ in leaves:
        got = f.head(leaf)
        if got is None:
            break
        kind, length, links = got
        if kind == b"DT":
            avail = min(length, f.size - leaf) - _HEAD.size - 8 * len(links)
            if f.whole(leaf, length):
                total, kept = total + avail, kept + 1
                continue
            clipped = (leaf, len(links), total, avail)
            break
        if kind == b"DZ" and f.whole(leaf, length):
            orig, zip_type, _, orig_len, zipped = _DZ.unpack(
                _exactly(f.body(leaf, length, len(links), _DZ.size), _DZ.size, leaf))
            if orig != b"DT" or zip_type not in (0, 1):
                return (f"a compressed block of '{orig.decode('latin-1')}' data (zip type {zip_type}) at byte "
                        f"{leaf:,}, not read in part")
            if zipped > length or orig_len > MAX_INFLATE * zipped + 64:  # deflate gives at most 1,032 bytes a byte
                raise _Damaged(f"the compressed block at byte {leaf:,} declares {orig_len:,} bytes from {zipped:,} "
                               "compressed, more than deflate gives (a damaged block)")
            total, kept = total + orig_len, kept + 1
            continue
        if kind == b"DZ":
            break  # a compressed block cut short: dropped, with every block after it
        return f"its data is in '{kind.decode('latin-1')}' blocks, which are not read in part"
    if clipped is not None:
        leaf, nlinks, before, avail = clipped
        keep_bytes = ((before + avail) // record) * record - before if record else 0
        if keep_bytes > 0:
            patches.append((leaf + 8, _u64(_HEAD.size + 8 * nlinks + keep_bytes)))
            total, kept = total + keep_bytes, kept + 1
    records = total // record if record else 0
    if kept < len(leaves):
        if kept == 0:
            patches.append((parent, _u64(0)))  # no block kept: the data group's data link cleared
        else:
            _, dl, index = leaves[kept - 1]
            if dl is not None:
                patches.append((dl, _rewrite_dl(f, dl, index + 1)))
    return records, patches


def _names(f: _File, cn: int) -> tuple[str, ...]:
    names: list[str] = []
    seen: set[int] = set()
    while cn and cn not in seen and len(names) <= NAMES_QUOTED:  # one more: are there more than quoted?
        seen.add(cn)
        got = f.head(cn)
        if got is None or got[0] != b"CN" or len(got[2]) < 3:
            break
        name = f.text(got[2][2])
        if name and name not in ("time", "t", "timestamps") and not name.endswith(".t"):
            names.append(name)
        cn = got[2][0]
    return tuple(names)


def plan_cut(path: str | Path) -> MdfCut:
    """What the MDF4 ``path``, cut short, keeps (see the module docs); a ValueError saying why when
    nothing in it can be read (its channel blocks are past the cut, or the file is damaged)."""
    p = Path(path)
    size = p.stat().st_size
    with open(p, "rb") as fh:
        f = _File(fh, size)
        try:
            return _plan(f)
        except _Damaged as exc:
            raise ValueError(str(exc)) from None


def _plan(f: _File) -> MdfCut:
    hd = f.head(64)
    if hd is None or hd[0] != b"HD" or not f.whole(64, hd[1]) or len(hd[2]) < 6:
        raise ValueError("its header block is cut")
    patches: list[tuple[int, bytes]] = []
    for i in range(1, 6):  # file history, channel hierarchy, attachments, events, comment: kept when whole
        if hd[2][i] and not f.tree_whole(hd[2][i], follow_data=True):
            patches.append((_link_at(64, i), _u64(0)))
    groups: list[Group] = []
    prev, dg, number, seen = _link_at(64, 0), hd[2][0], 0, set()
    while dg and dg not in seen:
        seen.add(dg)
        number += 1
        got = f.head(dg)
        if got is None or got[0] != b"DG" or not f.whole(dg, got[1]) or len(got[2]) < 4:
            groups.append(Group(number, (), 0, 0, "its blocks are past the cut, with any group after it"))
            patches.append((prev, _u64(0)))
            break
        _, length, links = got
        lost = _group_lost(f, dg, links)
        kept = declared = 0
        names: tuple[str, ...] = ()
        if lost is None:
            cg = links[1]
            cg_head = f.head(cg)
            if cg_head is None or cg_head[0] != b"CG" or len(cg_head[2]) < 2:
                raise _Damaged(f"no channel group block at byte {cg:,} (a damaged link or block header)")
            names = _names(f, cg_head[2][1])
            _, declared, _, _, data_bytes, inval_bytes = _CG.unpack(
                _exactly(f.body(cg, cg_head[1], len(cg_head[2]), _CG.size), _CG.size, cg))
            rec_id = f.body(dg, length, len(links), 1)
            record = (rec_id[0] if rec_id else 0) + data_bytes + inval_bytes
            if cg_head[2][0]:  # several channel groups' records interleave (unsorted): whole or lost
                if links[2] and not f.tree_whole(links[2], follow_data=True):
                    lost = "its records of several channel groups interleave (unsorted) and its data is cut"
                kept = declared
            else:  # the records counted from the data kept (an unfinalised file may not have counted them)
                got_data = _group_data(f, dg, links, record)
                if isinstance(got_data, str):
                    lost = got_data
                else:
                    kept, more = got_data
                    patches += more
                    if kept != declared:
                        patches.append((cg + _HEAD.size + 8 * len(cg_head[2]) + 8, _u64(kept)))
        if lost is not None:
            patches.append((prev, _u64(links[0])))  # unlinked: the previous link skips it
        else:
            prev = _link_at(dg, 0)
        groups.append(Group(number, names, kept, declared, lost))
        dg = links[0]
    kept_groups = [g for g in groups if g.lost is None]
    if not kept_groups:
        raise ValueError("no channel group's blocks are whole before the cut (a writer that puts them after the "
                         "data, as asammdf's MDF.save and python-can's MF4 logger do, loses them all in a cut "
                         "before the last few percent of the file)")
    if not any(g.kept for g in kept_groups):
        raise ValueError("no complete record of any channel group is before the cut")
    return MdfCut(f.size, tuple(patches), tuple(groups))


def _group_lost(f: _File, dg: int, links: tuple[int, ...]) -> str | None:
    """Why the data group at ``dg`` cannot be read (None: its channel blocks are whole)."""
    if not links[1]:
        return "it has no channel group"
    for i in (1, 3):
        if links[i] and not f.tree_whole(links[i], follow_data=False):
            return "its channel blocks are past the cut"
    return None


def repaired_copy(path: str | Path, cut: MdfCut) -> Path:
    """A temporary copy of ``path`` with ``cut``'s patches written (the caller removes it): an MDF4 whose
    blocks all end inside it."""
    fd, name = tempfile.mkstemp(prefix="pyrhonn-cut-", suffix=".mf4")
    os.close(fd)
    copy = Path(name)
    try:
        shutil.copyfile(path, copy)
        with open(copy, "r+b") as fh:
            for at, raw in cut.patches:
                fh.seek(at)
                fh.write(raw)
    except BaseException:
        copy.unlink(missing_ok=True)
        raise
    return copy
