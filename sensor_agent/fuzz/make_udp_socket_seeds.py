#!/usr/bin/env python3
"""Writes the seeds of ave_fuzz_velodyne_udp_socket (see velodyne_udp_socket_fuzz.cc for the
record format) into CORPUS/velodyne_udp_socket: the ave_fuzz_velodyne_udp seeds' packets as
raw 1206-byte records, written valid packets (a sweep every 10), and junk datagrams of 0, 1,
1205, 1207, 65507 bytes between them.

    sensor_agent/fuzz/make_udp_socket_seeds.py sensor_agent/fuzz/corpus
"""
import os
import sys

PACKET = 1206


def raw(packet):  # kind 1: a 1206-byte datagram
    return b"\x01" + packet


def written(byte):  # kind 2: a valid packet from the packet writer
    return b"\x02" + bytes([byte])


def junk(length, fill=b"\xa5"):  # kind 0: a datagram of `length` bytes, `fill` repeated
    return b"\x00" + length.to_bytes(2, "big") + bytes([len(fill)]) + fill


EMPTY = b"\x03"


def main():
    corpus = sys.argv[1]
    out_dir = os.path.join(corpus, "velodyne_udp_socket")
    os.makedirs(out_dir, exist_ok=True)
    udp_dir = os.path.join(corpus, "velodyne_udp")
    seeds = {}
    for name in sorted(os.listdir(udp_dir)):
        data = open(os.path.join(udp_dir, name), "rb").read()
        packets = [data[i:i + PACKET] for i in range(1, len(data), PACKET)]
        seeds["from_udp_" + name] = data[:1] + b"".join(raw(p) for p in packets if len(p) == PACKET)
        # The same packets with junk of every awkward size between them.
        body = b""
        for i, p in enumerate(packets):
            if len(p) == PACKET:
                body += raw(p)
            body += [junk(0), junk(1), junk(PACKET - 1), junk(PACKET + 1), junk(65507), EMPTY][i % 6]
        seeds["junk_between_" + name] = data[:1] + body
    for opt, model in ((0, "unknown"), (3, "vlp16"), (2, "hdl32e"), (1, "hdl64e"), (7, "vlp16_30m")):
        seeds["written_" + model] = bytes([opt]) + b"".join(written(b) for b in range(22))
        seeds["written_junk_" + model] = bytes([opt]) + b"".join(
            written(b) + (junk(b * 997 % 65508, bytes([b])) if b % 3 == 0 else EMPTY if b % 3 == 1 else b"")
            for b in range(22))
    for name, data in seeds.items():
        with open(os.path.join(out_dir, name), "wb") as f:
            f.write(data)


if __name__ == "__main__":
    main()
