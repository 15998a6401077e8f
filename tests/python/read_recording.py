#!/usr/bin/env python3
"""Reads a sonoflow MCAP recording with the PyPI `mcap` package and decodes one raw RF frame
with numpy alone (fixed offsets documented in docs/recording.md, "Reading recordings from Python").

usage: read_recording.py RECORDING.mcap EXPECT.json
EXPECT.json: {"topic", "frame_id", "n_channels", "n_samples", "fs", "values": [[ch, k, v], ...],
              "sum": float, "messages": {topic: count}}
Exits non-zero (with a message) on any mismatch.
"""
import json
import sys

import numpy as np
from mcap.reader import make_reader

# sonoflow_msgs/MsgHeaderV1 (64 bytes) and RfFrameHeaderV3 (1184 bytes), little endian.
MSG_HEADER = [
    ("seq", "<u8"), ("frame_id", "<u8"), ("t_valid", "<f8"), ("t_pub_ns", "<u8"),
    ("compute_ns", "<u8"), ("incarnation", "<u4"), ("flags", "<u4"), ("source_id", "<u4"),
    ("schema_minor", "<u4"), ("reserved", "<u4", (2,)),
]
RF_HEADER = np.dtype([
    ("common", np.dtype(MSG_HEADER)),
    ("fs", "<f8"), ("t0", "<f8"), ("fc", "<f8"), ("c", "<f8"), ("pitch", "<f8"),
    ("tx_angle", "<f8"), ("prf", "<f8"), ("element_width", "<f8"), ("radius", "<f8"),
    ("n_channels", "<u4"), ("n_samples", "<u4"), ("tx_id", "<u4"), ("sample_format", "<u4"),
    ("packet", "<u4"), ("frame_in_packet", "<u4"), ("tx_delays", "<f4", (256,)),
])
assert RF_HEADER.itemsize == 1184, RF_HEADER.itemsize


def decode_rf(data: bytes):
    """Raw RF record -> (header, array [n_channels, n_samples])."""
    if data[:4] != b"\x00\x01\x00\x00":
        raise ValueError("not a CDR little-endian record")
    hdr = np.frombuffer(data, dtype=RF_HEADER, count=1, offset=4)[0]
    n = int(np.frombuffer(data, dtype="<u4", count=1, offset=4 + RF_HEADER.itemsize)[0])
    payload = np.frombuffer(data, dtype="<f4", count=n, offset=8 + RF_HEADER.itemsize)
    return hdr, payload.reshape(int(hdr["n_channels"]), int(hdr["n_samples"]))


def main() -> int:
    path, expect_path = sys.argv[1], sys.argv[2]
    with open(expect_path) as f:
        expect = json.load(f)
    counts = {}
    found = None
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == expect["topic"]:
                if schema.encoding != "ros2msg" or channel.message_encoding != "cdr":
                    print(f"unexpected encodings {schema.encoding}/{channel.message_encoding}")
                    return 1
                hdr, rf = decode_rf(message.data)
                if int(hdr["common"]["frame_id"]) == expect["frame_id"]:
                    found = (schema, hdr, rf, message.data)
    for topic, n in expect["messages"].items():
        if counts.get(topic) != n:
            print(f"topic {topic}: {counts.get(topic)} messages, expected {n}")
            return 1
    if found is None:
        print(f"frame {expect['frame_id']} of {expect['topic']} not found")
        return 1
    schema, hdr, rf, raw = found
    if rf.shape != (expect["n_channels"], expect["n_samples"]) or float(hdr["fs"]) != expect["fs"]:
        print(f"shape {rf.shape} fs {hdr['fs']} differ from {expect}")
        return 1
    for ch, k, v in expect["values"]:
        if rf[ch, k] != np.float32(v):
            print(f"rf[{ch},{k}] = {rf[ch, k]!r}, expected {v!r}")
            return 1
    total = float(rf.astype(np.float64).sum())
    if abs(total - expect["sum"]) > 1e-9 * max(1.0, abs(expect["sum"])) + 1e-6:
        print(f"sum {total} != {expect['sum']}")
        return 1
    # The ros2msg schema stored in the file must describe the same bytes: decode with the
    # reference ROS 2 decoder when it is installed.
    try:
        from mcap_ros2.decoder import DecoderFactory
    except ImportError:
        print("mcap-ros2-support not installed: schema check skipped")
    else:
        decoder = DecoderFactory().decoder_for("cdr", schema)
        msg = decoder(raw)
        if (msg.header.n_channels, msg.header.n_samples) != rf.shape or msg.header.common.frame_id != expect["frame_id"]:
            print("ros2 decoder disagrees on the header")
            return 1
        if len(msg.data) != rf.size or msg.data[0] != rf.flat[0] or msg.data[-1] != rf.flat[-1]:
            print("ros2 decoder disagrees on the payload")
            return 1
        print("ros2msg schema decodes the same header and payload")
    print(f"ok: {sum(counts.values())} messages, frame {expect['frame_id']} decoded with numpy")
    return 0


if __name__ == "__main__":
    sys.exit(main())
