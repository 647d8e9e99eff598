#!/usr/bin/env python3
"""Packs one frame set of an `ave-sim studio` directory for carve_gpu.cu (which has no PNG or
JSON reader, so it runs on a bare GPU machine): every camera's 3x4 pixel projection
P = K [R^T | -R^T t] (world_from_camera = (R, t), OpenCV pixel centres at integers, no
distortion: the studio's cameras have none, checked) and its silhouette mask.

  studio_frameset_raw.py STUDIO_DIR FRAME OUT.raw
Layout (little-endian): u32 cameras, u32 width, u32 height, then per camera f64 P[12] (row-major)
and width*height mask bytes (255 = actor)."""
import json, struct, sys, zlib


def read_gray_png(path):
    data = open(path, 'rb').read()
    if data[:8] != b'\x89PNG\r\n\x1a\n':
        sys.exit(f'{path}: not a PNG')
    pos, idat = 8, b''
    w = h = None
    while pos < len(data):
        n, kind = struct.unpack('>I4s', data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b'IHDR':
            w, h, depth, color, _, _, interlace = struct.unpack('>IIBBBBB', body)
            if depth != 8 or color != 0 or interlace != 0:
                sys.exit(f'{path}: want an 8-bit grey, non-interlaced PNG')
        elif kind == b'IDAT':
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    out, prev = bytearray(), bytearray(w)
    for y in range(h):
        f, line = raw[y * (w + 1)], bytearray(raw[y * (w + 1) + 1:(y + 1) * (w + 1)])
        for x in range(w):
            a = line[x - 1] if x else 0
            b, c = prev[x], (prev[x - 1] if x else 0)
            if f == 1: line[x] = (line[x] + a) & 255
            elif f == 2: line[x] = (line[x] + b) & 255
            elif f == 3: line[x] = (line[x] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        out += line
        prev = line
    return w, h, bytes(out)


def main():
    studio, frame, out_path = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    cal = json.load(open(f'{studio}/calibration.json'))
    cams = cal['cameras']
    blob = bytearray()
    size = None
    for c in cams:
        if any(d != 0 for d in c['distortion']):
            sys.exit(f"camera {c['id']}: has lens distortion; carve_gpu.cu projects pinhole only")
        q = c['world_from_camera']
        w_, x, y, z = q['qw'], q['qx'], q['qy'], q['qz']
        n = (w_ * w_ + x * x + y * y + z * z) ** 0.5
        w_, x, y, z = w_ / n, x / n, y / n, z / n
        R = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w_), 2 * (x * z + y * w_)],
             [2 * (x * y + z * w_), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w_)],
             [2 * (x * z - y * w_), 2 * (y * z + x * w_), 1 - 2 * (x * x + y * y)]]
        t = [q['tx'], q['ty'], q['tz']]
        Rt = [[R[j][i] for j in range(3)] for i in range(3)]  # camera_from_world rotation
        tc = [-sum(Rt[i][k] * t[k] for k in range(3)) for i in range(3)]
        K = [[c['fx'], 0, c['cx']], [0, c['fy'], c['cy']], [0, 0, 1]]
        P = [[sum(K[i][k] * (Rt[k][j] if j < 3 else tc[k]) for k in range(3)) for j in range(4)] for i in range(3)]
        w, h, mask = read_gray_png(f"{studio}/{c['id']}/mask_{frame:04d}.png")
        if size and size != (w, h):
            sys.exit(f"camera {c['id']}: mask is {w}x{h}, the first was {size[0]}x{size[1]}")
        size = (w, h)
        blob += struct.pack('<12d', *[P[i][j] for i in range(3) for j in range(4)]) + mask
    open(out_path, 'wb').write(struct.pack('<III', len(cams), size[0], size[1]) + blob)
    print(f'{out_path}: {len(cams)} cameras, {size[0]}x{size[1]}')


if __name__ == '__main__':
    main()
