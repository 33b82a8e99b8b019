#!/usr/bin/env python3
"""Where a composed view is brighter or darker than the path tracer, with the noise averaged
away: bias_map.py OUT.png REFERENCE.exr GROUP [GROUP ...], each GROUP a comma-separated list of
view EXRs (irradcast-bake's view.exr, the same camera, other seeds) whose mean makes one panel.
A panel is the group's mean luminance over the reference's, both box-filtered 11 x 11 pixels:
blue 0.7 or darker, white 1, red 1.3 or brighter. Reads the bake's EXRs (float RGB, no or ZIP
compression); standard library only, like png_montage.py.
bias_map.py --mean REFERENCE.exr VIEW.exr ...: prints each view's mean luminance over the
reference's instead."""
import struct
import sys
import zlib

RADIUS = 5  # the box filter: 11 x 11 pixels
GAP = 6     # grey pixels between panels


def read_exr_luminance(path):
    data = open(path, "rb").read()
    if data[:4] != b"\x76\x2f\x31\x01":
        sys.exit(f"{path}: not an OpenEXR file")
    pos, attrs = 8, {}
    while True:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        if not name:
            pos = end + 1
            break
        tend = data.index(b"\0", end + 1)
        size = struct.unpack("<i", data[tend + 1:tend + 5])[0]
        attrs[name] = data[tend + 5:tend + 5 + size]
        pos = tend + 5 + size
    x0, y0, x1, y1 = struct.unpack("<4i", attrs["dataWindow"])
    width, height = x1 - x0 + 1, y1 - y0 + 1
    lines = {0: 1, 2: 1, 3: 16}.get(attrs["compression"][0])
    if lines is None:
        sys.exit(f"{path}: compression {attrs['compression'][0]} not read here")
    blocks = (height + lines - 1) // lines
    offsets = struct.unpack(f"<{blocks}Q", data[pos:pos + 8 * blocks])
    lum = [None] * height
    for off in offsets:
        y, size = struct.unpack("<ii", data[off:off + 8])
        chunk = data[off + 8:off + 8 + size]
        n = min(lines, height - (y - y0))
        if size < n * width * 12:  # ZIP: inflate, undo the predictor, then the interleave
            t = bytearray(zlib.decompress(chunk))
            for k in range(1, len(t)):
                t[k] = (t[k - 1] + t[k] - 128) & 255
            half = (len(t) + 1) // 2
            out = bytearray(len(t))
            out[0::2], out[1::2] = t[:half], t[half:]
            chunk = bytes(out)
        for r in range(n):
            row = chunk[r * width * 12:(r + 1) * width * 12]
            b = struct.unpack(f"<{width}f", row[:width * 4])  # channels B, G, R
            g = struct.unpack(f"<{width}f", row[width * 4:width * 8])
            red = struct.unpack(f"<{width}f", row[width * 8:])
            lum[y - y0 + r] = [0.2126 * red[x] + 0.7152 * g[x] + 0.0722 * b[x] for x in range(width)]
    return width, height, lum


def box_filtered(width, height, img):
    s = [[0.0] * (width + 1) for _ in range(height + 1)]
    for y in range(height):
        acc = 0.0
        for x in range(width):
            acc += img[y][x]
            s[y + 1][x + 1] = s[y][x + 1] + acc
    out = [[0.0] * width for _ in range(height)]
    for y in range(height):
        ya, yb = max(0, y - RADIUS), min(height, y + RADIUS + 1)
        for x in range(width):
            xa, xb = max(0, x - RADIUS), min(width, x + RADIUS + 1)
            out[y][x] = s[yb][xb] - s[ya][xb] - s[yb][xa] + s[ya][xa]
    return out


def colour(ratio):
    t = max(-1.0, min(1.0, (ratio - 1.0) / 0.3))
    if t < 0:
        return (int(255 * (1 + t)), int(255 * (1 + t)), 255)
    return (255, int(255 * (1 - t)), int(255 * (1 - t)))


def mean_ratios():
    width, height, ref = read_exr_luminance(sys.argv[2])
    total = sum(map(sum, ref))
    for f in sys.argv[3:]:
        w, h, img = read_exr_luminance(f)
        if (w, h) != (width, height):
            sys.exit(f"{f}: {w}x{h}, the reference is {width}x{height}")
        print(f"{f}: mean over the reference {sum(map(sum, img)) / total:.4f}")


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    if sys.argv[1] == "--mean":
        mean_ratios()
        return
    width, height, ref = read_exr_luminance(sys.argv[2])
    ref = box_filtered(width, height, ref)
    panels = []
    for group in sys.argv[3:]:
        files = group.split(",")
        mean = [[0.0] * width for _ in range(height)]
        for f in files:
            w, h, img = read_exr_luminance(f)
            if (w, h) != (width, height):
                sys.exit(f"{f}: {w}x{h}, the reference is {width}x{height}")
            for y in range(height):
                for x in range(width):
                    mean[y][x] += img[y][x] / len(files)
        mean = box_filtered(width, height, mean)
        panels.append([[mean[y][x] / ref[y][x] if ref[y][x] > 1e-9 else 1.0
                        for x in range(width)] for y in range(height)])
    rows = []
    for y in range(height):
        row = bytearray([0])
        for i, panel in enumerate(panels):
            if i:
                row += bytes([40, 40, 40]) * GAP
            for x in range(width):
                row += bytes(colour(panel[y][x]))
        rows.append(bytes(row))
    total = width * len(panels) + GAP * (len(panels) - 1)

    def chunk(kind, body):
        return (struct.pack(">I", len(body)) + kind + body +
                struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF))

    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", total, height, 8, 2, 0, 0, 0)) +
           chunk(b"IDAT", zlib.compress(b"".join(rows), 9)) + chunk(b"IEND", b""))
    open(sys.argv[1], "wb").write(png)


if __name__ == "__main__":
    main()
