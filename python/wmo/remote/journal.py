"""Durable storage of a hosted scene: a checkpoint plus a journal of the edits after it.

A scene's directory holds

- ``scene.ckpt``: the scene's document (:meth:`SceneModel.to_document`, msgpack),
  replaced atomically (written to a temporary file, fsync'd, renamed over the old one,
  the directory fsync'd);
- ``journal.log``: the edits applied since, appended in server order as records of
  ``uint32 length | uint32 crc32 | msgpack {"seq", "op", "args", "client"}`` (little
  endian; length and CRC of the msgpack bytes).

The server appends a tick's edits and fsyncs the journal *before* it acknowledges any
of them (group commit, one fsync per simulation tick with edits), so an acknowledged
edit is on disk. After a crash (even SIGKILL mid-write) :meth:`SceneStore.load` returns
the checkpoint and the complete records after it; a torn last record (never
acknowledged, as its fsync did not return) is cut off. Replaying those records on the
checkpoint restores every acknowledged edit. The simulated motion between the
checkpoint and the crash is not journaled and is lost (a checkpoint is written every
``checkpoint_interval`` seconds and on a clean shutdown).
"""
from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path

import msgpack

__all__ = ["SceneStore", "JournalError"]

_HEADER = struct.Struct("<II")
#: A record larger than this is corruption, not an edit (the server caps messages at
#: well under it).
MAX_RECORD_BYTES = 64 << 20


class JournalError(RuntimeError):
    """The checkpoint is unreadable (the journal's torn tail is not an error)."""


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class SceneStore:
    """The checkpoint and journal of one scene, in `directory` (created if missing)."""

    def __init__(self, directory: str | os.PathLike):
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.checkpoint_path = self.directory / "scene.ckpt"
        self.journal_path = self.directory / "journal.log"
        self._journal = None
        self.records_since_checkpoint = 0

    def load(self, repair: bool = True) -> tuple[dict | None, list[dict]]:
        """The last checkpoint (None if there is none) and the journal's complete records
        with a sequence number above the checkpoint's, in order. With `repair` (the
        server, at start) cuts a torn tail off the journal file so that appends continue
        after the last good record; without it the files are only read (safe while a
        server is appending)."""
        doc = None
        if self.checkpoint_path.exists():
            try:
                doc = msgpack.unpackb(self.checkpoint_path.read_bytes(), raw=False, strict_map_key=False)
            except Exception as e:  # a checkpoint is only ever replaced whole
                raise JournalError(f"{self.checkpoint_path}: unreadable checkpoint ({e})") from e
        base = doc["edit_seq"] if doc else 0
        records, good = [], 0
        if self.journal_path.exists():
            data = self.journal_path.read_bytes()
            pos = 0
            while pos + _HEADER.size <= len(data):
                length, crc = _HEADER.unpack_from(data, pos)
                end = pos + _HEADER.size + length
                if length > MAX_RECORD_BYTES or end > len(data):
                    break
                payload = data[pos + _HEADER.size:end]
                if zlib.crc32(payload) != crc:
                    break
                try:
                    rec = msgpack.unpackb(payload, raw=False, strict_map_key=False)
                except Exception:
                    break
                pos = good = end
                if rec["seq"] > base:
                    records.append(rec)
            if repair and good < len(data):
                with open(self.journal_path, "r+b") as f:
                    f.truncate(good)
                    f.flush()
                    os.fsync(f.fileno())
        self.records_since_checkpoint = len(records)
        return doc, records

    def append(self, records: list[dict]) -> None:
        """Appends `records` and returns once they are on disk (fsync)."""
        if not records:
            return
        if self._journal is None:
            self._journal = open(self.journal_path, "ab")
        buf = bytearray()
        for rec in records:
            payload = msgpack.packb(rec, use_bin_type=True)
            buf += _HEADER.pack(len(payload), zlib.crc32(payload))
            buf += payload
        self._journal.write(buf)
        self._journal.flush()
        os.fsync(self._journal.fileno())
        self.records_since_checkpoint += len(records)

    def checkpoint(self, doc: dict) -> None:
        """Replaces the checkpoint with `doc` (atomically) and empties the journal, whose
        records `doc` now includes. A crash between the two leaves records at or below
        the checkpoint's sequence number, which load() skips."""
        tmp = self.checkpoint_path.with_suffix(".tmp")
        with open(tmp, "wb") as f:
            f.write(msgpack.packb(doc, use_bin_type=True))
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.checkpoint_path)
        _fsync_dir(self.directory)
        if self._journal is not None:
            self._journal.close()
        self._journal = open(self.journal_path, "wb")
        os.fsync(self._journal.fileno())
        self.records_since_checkpoint = 0

    def close(self) -> None:
        if self._journal is not None:
            self._journal.close()
            self._journal = None
