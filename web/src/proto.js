// The protocol's messages (proto/irradcast.proto, parsed at build time by web/build.mjs) with
// protobufjs's light runtime. One binary WebSocket message = one serialized Envelope.
import protobuf from 'protobufjs/light.js';
import descriptor from 'irradcast-proto';

const root = protobuf.Root.fromJSON(descriptor);
export const Envelope = root.lookupType('irradcast.wire.Envelope');
export const SceneData = root.lookupType('irradcast.wire.SceneData');
export const PROTOCOL_VERSION = 1;

export const encode = (obj) => Envelope.encode(Envelope.fromObject(obj)).finish();
export const decode = (bytes) => Envelope.decode(bytes);
// uint64 fields arrive as numbers or, where protobufjs found long.js, as Long objects.
export const num = (v) => (v === undefined || v === null ? 0 : typeof v === 'number' ? v : Number(v.toString()));
export const ERROR_NAMES = root.lookupEnum('irradcast.wire.ErrorCode').valuesById;
