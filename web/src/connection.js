// The protocol's client side over a WebSocket (the page's ClientSession,
// client/src/client_session.cpp): Hello (resuming with the scene and tile versions held), the
// scene download checked against its SHA-256, Subscribe, TileUpdates into the lightmap textures,
// applied SceneEdit broadcasts in revision order, Stats, Pings for the idle timer, reconnection
// with back-off. Every message from the server is checked; a bad one ends the connection with a
// one-line reason shown in the overlay.
import { decode, encode, num, PROTOCOL_VERSION, decodeSceneData, ERROR_NAMES } from './proto.js';
import { sha256 } from './sha256.js';
import { decodeTile, inflateUpTo } from './codec.js';
import { readScene } from './scene.js';
import { applyProbeVolume } from './volume.js';

const MAX_SCENE_BYTES = 1 << 30;
const equalBytes = (a, b) => a && b && a.length === b.length && a.every((x, i) => x === b[i]);

export class Connection {
  // handlers: sceneReady(model, welcome), subscribed(), tile(lightmap, x0, y0, w, h, words),
  // tileBase(lightmap, x0, y0, w, h), edit(message), poses(message), avatars(message) (with
  // options.presence), volume(v), stats(stats), status(text), error(text)
  constructor(url, options, handlers) {
    this.url = url;
    this.options = options;
    this.h = handlers;
    this.scene = null;         // { model, hash, welcome }
    this.volume = null;        // the probe volume held (volume.js)
    this.versions = null;      // per lightmap, per tile: version held (0 = none)
    this.epoch = 0;
    this.counters = { bytes: 0, tiles: 0, frames: 0, edits: 0, volumes: 0, poses: 0, avatars: 0, stats: 0, connections: 0,
      byEncoding: [0, 0, 0] };
    this.backoff = 250;
    this.connect();
  }

  connect() {
    this.ws = new WebSocket(this.url);
    this.ws.binaryType = 'arraybuffer';
    this.phase = 'welcome';
    this.ws.onopen = () => {
      ++this.counters.connections;
      this.backoff = 250;
      this.send(this.hello());
    };
    this.ws.onmessage = (e) => {
      if (!(e.data instanceof ArrayBuffer)) return this.fail('a text message (the protocol is binary)');
      this.counters.bytes += e.data.byteLength;
      ++this.counters.frames;
      let env;
      try {
        env = decode(new Uint8Array(e.data));
      } catch (err) {
        return this.fail(`a message that is not an Envelope (${err.message})`);
      }
      try {
        this.onEnvelope(env);
      } catch (err) {
        this.fail(err.message);
      }
    };
    this.ws.onclose = (e) => {
      clearInterval(this.timer);
      this.phase = 'closed';  // until the next connection's Welcome: nothing is sent
      this.h.status(`disconnected (${e.code}${e.reason ? ' ' + e.reason : ''}); reconnecting`);
      setTimeout(() => this.connect(), this.backoff);
      this.backoff = Math.min(this.backoff * 2, 5000);
    };
  }

  fail(why) {
    this.h.error(why);
    try { this.ws.close(1002, 'protocol error'); } catch (_) { /* closed already */ }
  }

  // Whether the message went out: not while the connection is down.
  send(obj) {
    if (this.ws.readyState !== WebSocket.OPEN) return false;
    this.ws.send(encode(obj));
    return true;
  }

  hello() {
    const h = { protocol_version: PROTOCOL_VERSION, client_name: 'irradcast-web' };
    if (this.scene) {
      h.cached_scene_hash = this.scene.hash;
      h.known_epoch = this.epoch;
      h.known = [];
      this.versions.forEach((tiles, lightmap) => tiles.forEach((version, i) => {
        if (version > 0) h.known.push({ lightmap, tile_x: i % this.scene.welcome.lightmaps[lightmap].tiles_x,
          tile_y: Math.floor(i / this.scene.welcome.lightmaps[lightmap].tiles_x), version });
      }));
    }
    return { hello: h };
  }

  onEnvelope(env) {
    switch (env.msg) {
      case 'welcome': return this.onWelcome(env.welcome);
      case 'scene_chunk': return this.onChunk(env.scene_chunk);
      case 'tile_update': return this.onTile(env.tile_update);
      case 'scene_edit': return this.onEdit(env.scene_edit);
      case 'probe_volume': return this.onVolume(env.probe_volume);
      case 'poses': return this.onPoses(env.poses);
      case 'avatars':
        if (this.phase !== 'streaming') throw new Error('Avatars before the subscription');
        ++this.counters.avatars;
        return this.h.avatars(env.avatars);
      case 'stats':
        ++this.counters.stats;
        return this.h.stats(env.stats);
      case 'error': {
        const name = ERROR_NAMES[env.error.code] || env.error.code;
        return this.h.error(`server: ${name}: ${env.error.message}`);
      }
      case 'bye': return this.h.status(`server said bye: ${env.bye.reason}`);
      default: return undefined;  // Pong, and anything newer
    }
  }

  onWelcome(w) {
    if (this.phase !== 'welcome') throw new Error('an unexpected Welcome');
    if (w.protocol_version !== PROTOCOL_VERSION)
      throw new Error(`the server speaks protocol ${w.protocol_version}, this page ${PROTOCOL_VERSION}`);
    const epoch = num(w.tile_epoch);
    if (this.scene && epoch !== this.epoch) this.versions.forEach((v) => v.fill(0));
    this.epoch = epoch;
    this.welcome = w;
    const ping = Math.max(1000, Math.min(10000, (w.idle_timeout_ms || 30000) / 3));
    this.timer = setInterval(() => {
      this.send({ ping: { nonce: 1, time_us: Date.now() * 1000 } });
    }, ping);
    if (this.scene && equalBytes(w.scene_hash, this.scene.hash)) {
      this.phase = 'streaming';
      this.scene.welcome = w;
      this.h.status('resumed');
      return this.subscribe();
    }
    const total = num(w.scene_bytes);
    if (!(total > 0 && total <= MAX_SCENE_BYTES)) throw new Error(`the scene package size ${total} is out of range`);
    this.download = { data: new Uint8Array(total), at: 0 };
    this.phase = 'download';
    this.h.status(`downloading the scene (${(total / 1024).toFixed(0)} KiB)`);
    this.send({ scene_request: { offset: 0 } });
    return undefined;
  }

  onChunk(c) {
    if (this.phase !== 'download') throw new Error('a SceneChunk outside a download');
    const d = this.download;
    if (!equalBytes(c.scene_hash, this.welcome.scene_hash)) throw new Error('a SceneChunk of another scene');
    if (num(c.offset) !== d.at || num(c.total) !== d.data.length || d.at + c.data.length > d.data.length)
      throw new Error(`a SceneChunk at ${num(c.offset)} (+${c.data.length} of ${num(c.total)}), expected ${d.at}`);
    d.data.set(c.data, d.at);
    d.at += c.data.length;
    if (d.at < d.data.length) return;
    if (!equalBytes(sha256(d.data), this.welcome.scene_hash)) throw new Error('scene package: the SHA-256 does not match the Welcome');
    const model = readScene(decodeSceneData(inflateUpTo(d.data, MAX_SCENE_BYTES, 'scene package')));
    const w = this.welcome;
    if (w.lightmaps.length !== model.objects.length) throw new Error('the Welcome\'s lightmaps do not match the scene');
    model.objects.forEach((o, i) => {
      const l = w.lightmaps[i], ts = w.tile_size;
      if (l.width !== o.width || l.height !== o.height || !(ts > 0) ||
          l.tiles_x !== Math.ceil(o.width / ts) || l.tiles_y !== Math.ceil(o.height / ts))
        throw new Error(`lightmap ${i}: the Welcome's layout does not match the scene's`);
    });
    this.download = null;
    this.scene = { model, hash: w.scene_hash, welcome: w };
    this.versions = w.lightmaps.map((l) => new Array(l.tiles_x * l.tiles_y).fill(0));
    this.phase = 'streaming';
    this.h.sceneReady(model, w);
    this.subscribe();
  }

  subscribe() {
    this.send({ subscribe: { all: true, encoding: this.options.encoding, presence: !!this.options.presence } });
    this.h.subscribed();
    this.h.status('streaming');
  }

  onTile(t) {
    if (this.phase !== 'streaming') throw new Error('a TileUpdate before the subscription');
    const w = this.scene.welcome, ts = w.tile_size, l = w.lightmaps[t.lightmap];
    if (!l || t.tile_x >= l.tiles_x || t.tile_y >= l.tiles_y) throw new Error(`a TileUpdate for a tile that does not exist`);
    const x0 = t.tile_x * ts, y0 = t.tile_y * ts;
    const tw = Math.min(ts, l.width - x0), th = Math.min(ts, l.height - y0);
    if (t.width !== tw || t.height !== th) throw new Error(`a TileUpdate of ${t.width} x ${t.height} texels, expected ${tw} x ${th}`);
    const k = t.tile_y * l.tiles_x + t.tile_x, held = this.versions[t.lightmap][k], version = num(t.version);
    if (version <= held) return;
    if (t.encoding === 2 && num(t.base_version) !== held)
      throw new Error(`a delta on version ${num(t.base_version)} of a tile held at version ${held}`);
    const words = decodeTile(t.encoding, t.payload, tw, th, () => this.h.tileBase(t.lightmap, x0, y0, tw, th));
    this.versions[t.lightmap][k] = version;
    ++this.counters.tiles;
    ++this.counters.byEncoding[t.encoding];
    this.h.tile(t.lightmap, x0, y0, tw, th, words);
  }

  // The probe volume (volume.js): a bad one ends the connection like a bad tile.
  onVolume(m) {
    if (this.phase !== 'streaming') throw new Error('a ProbeVolume before the subscription');
    const v = applyProbeVolume(m, this.volume);
    if (v === this.volume) return undefined;  // another epoch's, without its layout
    this.volume = v;
    ++this.counters.volumes;
    return this.h.volume(v);
  }

  // Poses of dynamic nodes (edits.js applyPoses): not revisions; the newest come.
  onPoses(m) {
    if (this.phase !== 'streaming') throw new Error('Poses before the subscription');
    ++this.counters.poses;
    this.poseSequence = num(m.sequence);
    return this.h.poses(m);
  }

  onEdit(m) {
    if (!m.applied) return this.h.status(`edit ${num(m.request_id)} queued`);
    if (this.phase !== 'streaming') return undefined;  // the package after it will have it
    const rev = num(m.revision), have = this.scene.model.revision;
    if (rev <= have) return undefined;
    if (rev > have + 1) return this.reload('an edit was missed');
    ++this.counters.edits;
    this.scene.model.revision = rev;
    return this.h.edit(m);
  }

  // Loads the scene again on a new connection (after a missed edit).
  reload(why) {
    this.h.status(`${why}: loading the scene again`);
    this.scene = null;
    this.ws.close(1000, 'reload');
  }

  tilesHeld() {
    let held = 0, total = 0;
    if (this.versions) for (const v of this.versions) for (const x of v) { total += 1; held += x > 0 ? 1 : 0; }
    return { held, total };
  }
}
