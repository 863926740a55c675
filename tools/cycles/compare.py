"""Compare two PFM images (raypack's and the Cycles reference): whole-image mean per channel and
means over B x B blocks of pixels, relative differences. Optionally write both as PNGs (exposure,
sRGB) side by side with their difference.

  python3 tools/cycles/compare.py A.pfm B.pfm [--block 8] [--png OUT.png] [--exposure STOPS]

Only the standard library: no numpy needed.
"""
import argparse
import math
import struct
import sys
import zlib


def read_pfm(path):
    with open(path, "rb") as f:
        data = f.read()
    parts, pos = [], 0
    while len(parts) < 4:
        while data[pos:pos + 1].isspace():
            pos += 1
        start = pos
        while not data[pos:pos + 1].isspace():
            pos += 1
        parts.append(data[start:pos].decode())
    pos += 1
    kind, w, h, scale = parts[0], int(parts[1]), int(parts[2]), float(parts[3])
    if kind != "PF":
        sys.exit("%s: only colour PFM (PF)" % path)
    fmt = ("<" if scale < 0 else ">") + "%df" % (w * h * 3)
    vals = struct.unpack_from(fmt, data, pos)
    # PFM rows go from the bottom up: turn them top-down
    rows = [vals[(h - 1 - y) * w * 3:(h - y) * w * 3] for y in range(h)]
    return w, h, [v for r in rows for v in r]


def block_means(w, h, px, b):
    out = []
    for by in range(0, h - b + 1, b):
        for bx in range(0, w - b + 1, b):
            s = [0.0, 0.0, 0.0]
            for y in range(by, by + b):
                for x in range(bx, bx + b):
                    i = 3 * (y * w + x)
                    for c in range(3):
                        s[c] += px[i + c]
            out.append((bx, by, [v / (b * b) for v in s]))
    return out


def srgb8(v):
    v = max(0.0, min(1.0, v))
    v = 12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055
    return int(v * 255 + 0.5)


def write_png(path, w, h, rows):
    raw = b"".join(b"\x00" + bytes(r) for r in rows)
    def chunk(t, d):
        c = t + d
        return struct.pack(">I", len(d)) + c + struct.pack(">I", zlib.crc32(c) & 0xffffffff)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)) +
                chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("a")
    p.add_argument("b")
    p.add_argument("--block", type=int, default=8)
    p.add_argument("--min", type=float, default=0.01, help="blocks whose mean (B) is below this are skipped")
    p.add_argument("--png")
    p.add_argument("--exposure", type=float, default=0.0)
    p.add_argument("--scale", type=int, default=2, help="PNG pixel replication")
    a = p.parse_args()
    wa, ha, A = read_pfm(a.a)
    wb, hb, B = read_pfm(a.b)
    if (wa, ha) != (wb, hb):
        sys.exit("sizes differ: %dx%d vs %dx%d" % (wa, ha, wb, hb))
    w, h, n = wa, ha, wa * ha
    ma = [sum(A[c::3]) / n for c in range(3)]
    mb = [sum(B[c::3]) / n for c in range(3)]
    print("image %dx%d" % (w, h))
    print("mean A  %.5f %.5f %.5f" % tuple(ma))
    print("mean B  %.5f %.5f %.5f" % tuple(mb))
    print("A/B-1   %+.4f %+.4f %+.4f" % tuple(ma[c] / mb[c] - 1 for c in range(3)))
    ba, bb = block_means(w, h, A, a.block), block_means(w, h, B, a.block)
    worst = [(0.0, None)] * 3
    rms = [0.0] * 3
    cnt = [0] * 3
    for (x, y, va), (_, _, vb) in zip(ba, bb):
        for c in range(3):
            if vb[c] < a.min:
                continue
            cnt[c] += 1
            d = va[c] / vb[c] - 1
            rms[c] += d * d
            if abs(d) > abs(worst[c][0]):
                worst[c] = (d, (x, y))
    print("%dx%d blocks (of %d) with B mean >= %g per channel: %d %d %d" % ((a.block, a.block, len(bb), a.min) + tuple(cnt)))
    print("block A/B-1 rms  %.4f %.4f %.4f" % tuple(math.sqrt(rms[c] / max(cnt[c], 1)) for c in range(3)))
    for c in range(3):
        print("worst block %s: %+.4f at (%s)" % ("RGB"[c], worst[c][0], worst[c][1]))
    if a.png:
        k, s = 2.0 ** a.exposure, a.scale
        rows = []
        for y in range(h):
            row = []
            for x in range(w):
                i = 3 * (y * w + x)
                pa = [srgb8(k * A[i + c]) for c in range(3)]
                pb = [srgb8(k * B[i + c]) for c in range(3)]
                # difference: red where A is brighter, blue where B is, 10x
                la = sum(A[i:i + 3]) / 3
                lb = sum(B[i:i + 3]) / 3
                d = 10 * (la - lb) / max(lb, 1e-3)
                pd = [srgb8(max(d, 0)), 0, srgb8(max(-d, 0))]
                row.append(pa + pb + pd)
            full = []
            for part in range(3):
                for x in range(w):
                    full.extend(row[x][3 * part:3 * part + 3] * s)
                full.extend([255, 255, 255] * 2)
            for _ in range(s):
                rows.append(full)
        write_png(a.png, (w * s + 2) * 3, h * s, rows)
        print("wrote %s (A | B | 10x relative luminance difference, red: A brighter)" % a.png)


main()
