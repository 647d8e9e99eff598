#!/usr/bin/env python3
"""Writes the seed corpus of ave_fuzz_grpc_services (fusion_server/fuzz/grpc_services_fuzz.cc):
one valid call per RPC, encoded with protoc from text format. Run from the repository root:
    python3 fusion_server/fuzz/make_grpc_seeds.py
"""
import os
import struct
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUT = os.path.join(ROOT, "fusion_server", "fuzz", "corpus", "grpc_services")
JPEG = open(os.path.join(ROOT, "fusion_server", "fuzz", "corpus", "jpeg_header", "baseline_64x48"), "rb").read()
AVATAR = open(os.path.join(ROOT, "fusion_server", "fuzz", "corpus", "avatar_blob", "walk_2frames"), "rb").read()


def encode(message_type, text):
    return subprocess.run(
        ["protoc", "--encode=ave.v1." + message_type, "-I", os.path.join(ROOT, "proto"), "ave/v1/ave.proto"],
        input=text.encode(), capture_output=True, check=True).stdout


def call(rpc, credential, *messages):
    out = bytes([rpc, credential])
    for m in messages:
        out += struct.pack("<H", len(m)) + m
    return out


def octal(data):
    return "".join("\\%03o" % b for b in data)


def jpeg_text():
    return octal(JPEG)


HELLO = encode("SensorMessage", 'hello { camera_id: "fz" token: "t" software_version: "seed" '
                                'intrinsics { width: 64 height: 48 fx: 50 fy: 50 cx: 32 cy: 24 } }')
FRAME = encode("SensorMessage", 'frame { capture_time_ns: 1000000 sequence: 1 '
                                'pose { position { x: 1 y: 2 z: 3 } orientation { w: 1 } } '
                                'boxes { track_id: 7 score: 0.9 corners { x: 1 y: 1 } corners { x: 9 y: 1 } '
                                'corners { x: 9 y: 9 } corners { x: 1 y: 9 } } '
                                'jpeg: "%s" }' % jpeg_text())
SEEDS = {
    "sensor_stream": call(0, 1, HELLO, FRAME),
    "subscribe": call(1, 2, encode("SubscribeRequest", 'viewer_id: "v" max_rate_hz: 30 include_jpeg: true '
                                   'views { view_projection: [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1] }')),
    "static_model": call(2, 2, encode("StaticModelRequest", "known_version: 0")),
    "add_camera": call(3, 3, encode("AddCameraRequest", 'camera { id: "c2" name: "two" enabled: true '
                                    'intrinsics { width: 64 height: 48 fx: 50 fy: 50 cx: 32 cy: 24 } '
                                    'mounting_pose { orientation { w: 1 } } }')),
    "update_camera": call(4, 3, encode("UpdateCameraRequest", 'camera { id: "c2" name: "two b" enabled: false '
                                       'intrinsics { width: 64 height: 48 fx: 50 fy: 50 cx: 32 cy: 24 } '
                                       'mounting_pose { orientation { w: 1 } } }')),
    "remove_camera": call(5, 3, encode("RemoveCameraRequest", 'id: "c2"')),
    "list_cameras": call(6, 3, b""),
    "issue_token": call(7, 3, encode("IssueTokenRequest", 'role: "sensor" camera_id: "fz" label: "seed"')),
    "revoke_token": call(8, 3, encode("RevokeTokenRequest", 'token_id: "0123456789ab"')),
    "list_tokens": call(9, 3, b""),
    "no_credential": call(3, 0, encode("AddCameraRequest", 'camera { id: "c3" }')),
    # Issue 18: the server under the fuzzer records, so a replay can find the seed stream's frame.
    "replay": call(10, 2, encode("ReplayRequest", 'viewer_id: "v" start_time_ns: 1 end_time_ns: 9000000000000000000 '
                                 'rate: 16 include_jpeg: true max_updates: 4')),
    "recorded_spans": call(11, 2, encode("RecordedSpansRequest", 'camera_ids: "fz" merge_gap_ns: 1000000000')),
    # Issue 17: avatar sequences, put by an admin in one chunk, fetched and listed.
    "put_avatar": call(13, 3, encode("AvatarSequenceChunk", 'name: "seed-walk" chunk_index: 0 chunk_count: 1 '
                                     'total_bytes: %d data: "%s"' % (len(AVATAR), octal(AVATAR)))),
    "get_avatar": call(12, 2, encode("AvatarSequenceRequest", 'name: "seed-walk"')),
    "list_avatars": call(14, 3, b""),
}

os.makedirs(OUT, exist_ok=True)
for name, data in SEEDS.items():
    with open(os.path.join(OUT, name), "wb") as f:
        f.write(data)
print("wrote %d seeds to %s" % (len(SEEDS), OUT))
