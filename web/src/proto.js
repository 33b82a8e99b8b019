// The protocol's messages (proto/irradcast.proto; web/build.mjs parses it with protobufjs at build
// time into a JSON descriptor) encoded and decoded here by walking that descriptor. No protobuf
// runtime in the page: protobufjs's generates code with `new Function`, which the server's
// Content-Security-Policy (script-src 'self') rightly forbids. One binary WebSocket message = one
// serialized Envelope. Decoding is strict: truncated or overlong fields throw.
import descriptor from 'irradcast-proto';

export const PROTOCOL_VERSION = 1;
const pkg = descriptor.nested.irradcast.nested.wire.nested;
const SCALARS = new Set(['double', 'float', 'int32', 'uint32', 'sint32', 'int64', 'uint64', 'sint64',
  'fixed32', 'fixed64', 'sfixed32', 'sfixed64', 'bool', 'string', 'bytes']);
const WIRE = { double: 1, fixed64: 1, sfixed64: 1, float: 5, fixed32: 5, sfixed32: 5, string: 2, bytes: 2 };

// Per message type: its fields by number and in order, each with its resolved kind.
const types = new Map();
function typeOf(name, scope) {
  const key = `${scope ? scope.name + '.' : ''}${name}`;
  const found = (scope && scope.def.nested && scope.def.nested[name]) || pkg[name];
  if (!found) throw new Error(`proto: no type ${key}`);
  if (found.values) return { enum: true };
  if (!types.has(found)) {
    const t = { name, def: found, fields: [], byId: new Map() };
    types.set(found, t);
    const oneofOf = {};
    for (const [o, v] of Object.entries(found.oneofs || {})) for (const f of v.oneof) oneofOf[f] = o;
    for (const [fname, f] of Object.entries(found.fields || {})) {
      const field = { name: fname, id: f.id, repeated: f.rule === 'repeated', oneof: oneofOf[fname],
        optional: !!(f.options && f.options.proto3_optional) };
      if (SCALARS.has(f.type)) field.scalar = f.type;
      else {
        const sub = typeOf(f.type, t);
        if (sub.enum) field.scalar = 'int32';
        else field.message = sub;
      }
      field.wire = field.message ? 2 : WIRE[field.scalar] ?? 0;
      t.fields.push(field);
      t.byId.set(field.id, field);
    }
    t.fields.sort((a, b) => a.id - b.id);
  }
  return types.get(found);
}

const utf8in = new TextDecoder('utf-8', { fatal: false }), utf8out = new TextEncoder();

class Reader {
  constructor(bytes) {
    this.b = bytes;
    this.dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    this.pos = 0;
  }
  need(n) { if (this.pos + n > this.b.length) throw new Error('proto: truncated message'); }
  varint() {  // -> [low 32 bits, high 32 bits]
    let lo = 0, hi = 0;
    for (let i = 0; i < 10; ++i) {
      this.need(1);
      const x = this.b[this.pos++];
      if (i < 4) lo |= (x & 127) << (7 * i);
      else if (i === 4) { lo |= (x & 15) << 28; hi |= (x & 127) >> 4; }
      else hi |= (x & 127) << (7 * i - 32);
      if (x < 128) return [lo >>> 0, hi >>> 0];
    }
    throw new Error('proto: overlong varint');
  }
  u32() { return this.varint()[0]; }
  bytes() {
    const n = this.u32();
    this.need(n);
    return this.b.slice(this.pos, (this.pos += n));
  }
  scalar(type) {
    switch (type) {
      case 'uint32': return this.u32();
      case 'int32': return this.varint()[0] | 0;
      case 'sint32': { const v = this.u32(); return (v >>> 1) ^ -(v & 1); }
      case 'uint64': case 'int64': { const [lo, hi] = this.varint(); return hi * 4294967296 + lo; }
      case 'sint64': { const [lo, hi] = this.varint(); const v = hi * 4294967296 + lo; return v % 2 ? -(v + 1) / 2 : v / 2; }
      case 'bool': return this.varint().some((x) => x !== 0);
      case 'float': this.need(4); this.pos += 4; return this.dv.getFloat32(this.pos - 4, true);
      case 'double': this.need(8); this.pos += 8; return this.dv.getFloat64(this.pos - 8, true);
      case 'fixed32': this.need(4); this.pos += 4; return this.dv.getUint32(this.pos - 4, true);
      case 'sfixed32': this.need(4); this.pos += 4; return this.dv.getInt32(this.pos - 4, true);
      case 'fixed64': case 'sfixed64': this.need(8); this.pos += 8;
        return this.dv.getUint32(this.pos - 4, true) * 4294967296 + this.dv.getUint32(this.pos - 8, true);
      case 'string': return utf8in.decode(this.bytes());
      default: return this.bytes();
    }
  }
  skip(wire) {
    if (wire === 0) this.varint();
    else if (wire === 1) { this.need(8); this.pos += 8; }
    else if (wire === 2) { const n = this.u32(); this.need(n); this.pos += n; }
    else if (wire === 5) { this.need(4); this.pos += 4; }
    else throw new Error(`proto: wire type ${wire} is not supported`);
  }
}

// Decodes the reader's bytes up to `end` as message type t. Absent fields get proto3's defaults
// (repeated: [], numbers 0, bools false, strings '', bytes empty; messages and proto3 optional
// fields stay undefined); the set member of a oneof is named by the oneof (env.msg = 'welcome').
function decodeType(t, r, end) {
  const out = {};
  for (const f of t.fields) {
    if (f.repeated) out[f.name] = [];
    else if (f.scalar && !f.optional && !f.oneof)
      out[f.name] = f.scalar === 'string' ? '' : f.scalar === 'bytes' ? new Uint8Array(0) : f.scalar === 'bool' ? false : 0;
  }
  while (r.pos < end) {
    const tag = r.u32(), f = t.byId.get(tag >>> 3), wire = tag & 7;
    if (!f) { r.skip(wire); continue; }
    let value;
    if (f.repeated && f.scalar && wire === 2 && f.wire !== 2) {  // packed
      const e = r.u32() + r.pos;
      if (e > end) throw new Error('proto: truncated message');
      while (r.pos < e) out[f.name].push(r.scalar(f.scalar));
      if (r.pos !== e) throw new Error('proto: packed field overruns');
      continue;
    }
    if (wire !== f.wire) throw new Error(`proto: ${t.name}.${f.name} has wire type ${wire}`);
    if (f.message) {
      const n = r.u32(), e = r.pos + n;
      if (e > end) throw new Error('proto: truncated message');
      value = decodeType(f.message, r, e);
    } else value = r.scalar(f.scalar);
    if (f.repeated) out[f.name].push(value);
    else {
      out[f.name] = value;
      if (f.oneof) out[f.oneof] = f.name;
    }
  }
  if (r.pos !== end) throw new Error(`proto: ${t.name} overruns its length`);
  return out;
}

class Writer {
  constructor() { this.b = new Uint8Array(64); this.n = 0; }
  grow(k) {
    if (this.n + k <= this.b.length) return;
    const nb = new Uint8Array(Math.max(2 * this.b.length, this.n + k));
    nb.set(this.b.subarray(0, this.n));
    this.b = nb;
  }
  byte(x) { this.grow(1); this.b[this.n++] = x; }
  varint(v) {
    if (v < 0) {  // negative int32/int64: ten bytes of two's complement
      let x = BigInt.asUintN(64, BigInt(Math.trunc(v)));
      while (x >= 128n) { this.byte(Number(x & 127n) | 128); x >>= 7n; }
      this.byte(Number(x));
      return;
    }
    v = Math.floor(v);
    while (v >= 128) { this.byte((v % 128) | 128); v = Math.floor(v / 128); }
    this.byte(v);
  }
  raw(bytes) { this.grow(bytes.length); this.b.set(bytes, this.n); this.n += bytes.length; }
  fixed(n, set) { this.grow(n); set(new DataView(this.b.buffer, this.n, n)); this.n += n; }
  scalar(type, v) {
    switch (type) {
      case 'sint32': case 'sint64': this.varint(v >= 0 ? 2 * v : -2 * v - 1); break;
      case 'bool': this.varint(v ? 1 : 0); break;
      case 'float': this.fixed(4, (d) => d.setFloat32(0, v, true)); break;
      case 'double': this.fixed(8, (d) => d.setFloat64(0, v, true)); break;
      case 'fixed32': case 'sfixed32': this.fixed(4, (d) => d.setUint32(0, v >>> 0, true)); break;
      case 'fixed64': case 'sfixed64': this.fixed(8, (d) => { d.setUint32(0, v >>> 0, true); d.setUint32(4, Math.floor(v / 4294967296), true); }); break;
      case 'string': { const s = utf8out.encode(v); this.varint(s.length); this.raw(s); break; }
      case 'bytes': this.varint(v.length); this.raw(v); break;
      default: this.varint(Number(v));
    }
  }
  finish() { return this.b.slice(0, this.n); }
}

function isDefault(f, v) {
  if (v === undefined || v === null) return true;
  if (f.optional || f.oneof || f.message) return false;
  if (f.scalar === 'string' || f.scalar === 'bytes') return v.length === 0;
  return v === 0 || v === false;
}

function encodeType(t, obj, w) {
  for (const f of t.fields) {
    const v = obj[f.name];
    const one = (x) => {
      if (f.message) {
        const sub = encodeType(f.message, x, new Writer()).finish();
        w.varint((f.id << 3) | 2);
        w.varint(sub.length);
        w.raw(sub);
      } else {
        w.varint((f.id << 3) | f.wire);
        w.scalar(f.scalar, x);
      }
    };
    if (f.repeated) {
      if (!v || !v.length) continue;
      if (f.message || f.wire === 2) { for (const x of v) one(x); continue; }
      const packed = new Writer();
      for (const x of v) packed.scalar(f.scalar, x);
      const bytes = packed.finish();
      w.varint((f.id << 3) | 2);
      w.varint(bytes.length);
      w.raw(bytes);
    } else if (!isDefault(f, v)) one(v);
  }
  return w;
}

const Envelope = typeOf('Envelope'), SceneData = typeOf('SceneData');
export const encode = (obj) => encodeType(Envelope, obj, new Writer()).finish();
export const decode = (bytes) => decodeType(Envelope, new Reader(bytes), bytes.length);
export const decodeSceneData = (bytes) => decodeType(SceneData, new Reader(bytes), bytes.length);
export const num = (v) => (typeof v === 'number' ? v : 0);
export const ERROR_NAMES = Object.fromEntries(Object.entries(pkg.ErrorCode.values).map(([k, v]) => [v, k]));
