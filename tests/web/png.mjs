// Reads 8-bit RGB / RGBA PNG files (non-interlaced: what Chromium's screenshots and irradcast's
// write_png produce) into { width, height, rgb: Uint8Array }, and compares two images by the
// means of their 16 x 16 pixel blocks, for the browser viewer's tests.
import { readFileSync } from 'node:fs';
import { inflateSync } from 'node:zlib';

export function readPng(file) {
  const b = readFileSync(file);
  if (b.readUInt32BE(0) !== 0x89504e47) throw new Error(`${file}: not a PNG`);
  let at = 8, width = 0, height = 0, channels = 0;
  const idat = [];
  while (at < b.length) {
    const n = b.readUInt32BE(at), type = b.toString('ascii', at + 4, at + 8), data = b.subarray(at + 8, at + 8 + n);
    if (type === 'IHDR') {
      width = data.readUInt32BE(0);
      height = data.readUInt32BE(4);
      const depth = data[8], color = data[9], interlace = data[12];
      channels = color === 2 ? 3 : color === 6 ? 4 : 0;
      if (depth !== 8 || !channels || interlace) throw new Error(`${file}: only 8-bit RGB/RGBA, non-interlaced`);
    } else if (type === 'IDAT') idat.push(data);
    at += 12 + n;
  }
  const raw = inflateSync(Buffer.concat(idat)), stride = width * channels;
  const px = new Uint8Array(height * stride);
  for (let y = 0; y < height; ++y) {
    const f = raw[y * (stride + 1)], src = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let x = 0; x < stride; ++x) {
      const a = x >= channels ? px[y * stride + x - channels] : 0, up = y > 0 ? px[(y - 1) * stride + x] : 0;
      const c = x >= channels && y > 0 ? px[(y - 1) * stride + x - channels] : 0;
      let p = 0;
      if (f === 1) p = a;
      else if (f === 2) p = up;
      else if (f === 3) p = (a + up) >> 1;
      else if (f === 4) {
        const q = a + up - c, pa = Math.abs(q - a), pb = Math.abs(q - up), pc = Math.abs(q - c);
        p = pa <= pb && pa <= pc ? a : pb <= pc ? up : c;
      }
      px[y * stride + x] = (src[x] + p) & 255;
    }
  }
  const rgb = new Uint8Array(width * height * 3);
  for (let i = 0; i < width * height; ++i) for (let k = 0; k < 3; ++k) rgb[3 * i + k] = px[channels * i + k];
  return { width, height, rgb };
}

// Means of 16 x 16 blocks, per channel, in 8-bit units: the largest and the mean absolute
// difference of two same-sized images, and the fraction of blocks whose channels all differ by
// at most `tight`.
export function blockDifference(a, b, block = 16, tight = 2) {
  if (a.width !== b.width || a.height !== b.height)
    throw new Error(`image sizes differ: ${a.width} x ${a.height} and ${b.width} x ${b.height}`);
  const bx = Math.floor(a.width / block), by = Math.floor(a.height / block);
  let max = 0, sum = 0, within = 0;
  for (let j = 0; j < by; ++j)
    for (let i = 0; i < bx; ++i) {
      let worst = 0;
      for (let k = 0; k < 3; ++k) {
        let sa = 0, sb = 0;
        for (let y = j * block; y < (j + 1) * block; ++y)
          for (let x = i * block; x < (i + 1) * block; ++x) {
            sa += a.rgb[3 * (y * a.width + x) + k];
            sb += b.rgb[3 * (y * a.width + x) + k];
          }
        const d = Math.abs(sa - sb) / (block * block);
        worst = Math.max(worst, d);
        sum += d;
      }
      max = Math.max(max, worst);
      if (worst <= tight) ++within;
    }
  return { max, mean: sum / (bx * by * 3), blocks: bx * by, within: within / (bx * by) };
}

// The mean of all pixels (8-bit units): a rendered image is not black.
export function meanLevel(img) {
  let s = 0;
  for (const v of img.rgb) s += v;
  return s / img.rgb.length;
}
