// Builds irradcast's browser viewer: `node web/build.mjs OUT_DIR` writes OUT_DIR/index.html and
// OUT_DIR/viewer.js (web/CMakeLists.txt embeds every file of OUT_DIR in irradcast-server).
// viewer.js is web/src/main.js bundled by esbuild with three.js, protobufjs (light) and fzstd from
// web/node_modules (installed by deploy/install-deps.sh from package-lock.json); the protocol's
// descriptor is parsed from proto/irradcast.proto here, at build time, and bundled as JSON, so the
// page fetches nothing but itself. Works on node 18 (Debian 12) and later.
import { copyFileSync, mkdirSync, readFileSync } from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));

function fail(message) {
  console.error(`web/build.mjs: ${message}`);
  process.exit(1);
}

const out = process.argv[2];
if (!out || process.argv.length > 3) fail('usage: node web/build.mjs OUT_DIR');

let esbuild, protobuf;
try {
  esbuild = await import('esbuild');
  protobuf = (await import('protobufjs')).default;
} catch (e) {
  fail(`${e.message}\n  (run deploy/install-deps.sh, or npm ci in web/)`);
}

// The protocol's messages as a protobufjs JSON descriptor (field names as in the .proto file).
const protoFile = path.join(here, '..', 'proto', 'irradcast.proto');
const parsed = protobuf.parse(readFileSync(protoFile, 'utf8'), { keepCase: true });
const descriptor = JSON.stringify(parsed.root.toJSON());

const protoPlugin = {
  name: 'irradcast-proto',
  setup(build) {
    build.onResolve({ filter: /^irradcast-proto$/ }, () => ({ path: 'descriptor', namespace: 'irradcast-proto' }));
    build.onLoad({ filter: /.*/, namespace: 'irradcast-proto' }, () => ({ contents: descriptor, loader: 'json' }));
  },
};

mkdirSync(out, { recursive: true });
try {
  await esbuild.build({
    entryPoints: [path.join(here, 'src', 'main.js')],
    bundle: true,
    format: 'iife',
    platform: 'browser',
    target: ['es2020', 'chrome90', 'firefox90', 'safari15'],
    minify: true,
    legalComments: 'none',
    outfile: path.join(out, 'viewer.js'),
    plugins: [protoPlugin],
    logLevel: 'warning',
  });
} catch (e) {
  fail(`bundling failed: ${e.message}`);
}
copyFileSync(path.join(here, 'index.html'), path.join(out, 'index.html'));
