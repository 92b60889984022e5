"""logs/bulk_write.py against ``rosbags``' writer one message at a time: the same MCAP bytes
and the same ``metadata.yaml``, for a few messages, for many chunks (a chunk ends after the
message that takes it past 1 MiB, the next one may start with either topic), for payloads
of several lengths, and with messages written one by one after the bulk ones."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amsfe_sym.logs.bulk_write import write_many
from amsfe_sym.logs.encode import JOINT_STATE, encode_joint_states
from amsfe_sym.logs.source import typestore

TOPICS = ("/amsfe/estimate", "/amsfe/estimate_std")


def _bag(path: Path, stamps: list[int], payloads: list[list[bytes]], bulk: bool, tail: int) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer

    w = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    w.open()
    conns = [w.add_connection(t, JOINT_STATE, typestore=typestore()) for t in TOPICS]
    head = len(stamps) - tail
    if bulk:
        assert write_many(
            w, conns, np.asarray(stamps[:head], dtype=np.int64), [p[:head] for p in payloads]
        )
    else:
        for k in range(head):
            for j, c in enumerate(conns):
                w.write(c, stamps[k], payloads[j][k])
    for k in range(head, len(stamps)):  # one by one after the bulk write
        for j, c in enumerate(conns):
            w.write(c, stamps[k], payloads[j][k])
    w.close()


@pytest.mark.parametrize(
    ("joints", "count", "tail", "ragged"),
    [(2, 3, 0, False), (7, 9000, 0, False), (7, 9000, 5, False), (3, 7000, 0, True)],
    ids=["few", "many-chunks", "then-one-by-one", "ragged"],
)
def test_the_same_bytes_as_rosbags(
    tmp_path: Path, joints: int, count: int, tail: int, ragged: bool
) -> None:
    rng = np.random.default_rng(count)
    stamps = (1_700_000_000 * 10**9 + np.arange(count) * 10**6).tolist()
    names = [f"joint{i}" for i in range(joints)]
    x = rng.normal(size=(count, 2 * joints))
    est = encode_joint_states(stamps, names, x[:, :joints], x[:, joints:])
    std = encode_joint_states(stamps, names, np.abs(x[:, :joints]))
    if ragged:  # payloads of several lengths on one topic
        short = encode_joint_states(stamps, names[:1], x[:, :1])
        std = [s if k % 3 else short[k] for k, s in enumerate(std)]
    for how in ("one", "bulk"):  # (same bag name: the metadata records it)
        (tmp_path / how).mkdir()
        _bag(tmp_path / how / "bag", stamps, [est, std], bulk=how == "bulk", tail=tail)
    a, b = (tmp_path / how / "bag" / "bag.mcap" for how in ("one", "bulk"))
    assert a.read_bytes() == b.read_bytes()
    ma, mb = (tmp_path / how / "bag" / "metadata.yaml" for how in ("one", "bulk"))
    assert ma.read_text() == mb.read_text()


def test_an_unknown_writer_state_is_left_alone(tmp_path: Path) -> None:
    """A compressed bag (or anything else): False, nothing written; the caller writes."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    w = Writer(tmp_path / "z", version=9, storage_plugin=StoragePlugin.MCAP)
    w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    w.open()
    c = w.add_connection(TOPICS[0], JOINT_STATE, typestore=typestore())
    assert not write_many(w, [c], np.asarray([1, 2]), [[b"\0" * 8, b"\0" * 8]])
    assert w.counts[c.id] == 0
    w.close()
