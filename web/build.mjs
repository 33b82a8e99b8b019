// Builds the viewer page's files into OUT_DIR (node build.mjs OUT_DIR): index.html and
// viewer.js. This minimal version copies index.html and writes a viewer.js that opens the
// protocol's WebSocket (/ws on the page's own host) and logs what arrives; the real page bundles
// web/src with esbuild.
import { copyFileSync, mkdirSync, writeFileSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const out = process.argv[2];
if (!out) {
  console.error('usage: node build.mjs OUT_DIR');
  process.exit(2);
}
const here = dirname(fileURLToPath(import.meta.url));
mkdirSync(out, { recursive: true });
copyFileSync(join(here, 'index.html'), join(out, 'index.html'));
writeFileSync(join(out, 'viewer.js'), `// irradcast viewer (minimal): opens the protocol's WebSocket.
const scheme = location.protocol === 'https:' ? 'wss:' : 'ws:';
const socket = new WebSocket(scheme + '//' + location.host + '/ws');
socket.binaryType = 'arraybuffer';
socket.onopen = () => { document.getElementById('status').textContent = 'irradcast: connected'; };
socket.onmessage = (e) => console.log('irradcast: message of', e.data.byteLength, 'bytes');
socket.onclose = (e) => console.log('irradcast: closed', e.code, e.reason);
`);
