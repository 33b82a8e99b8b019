#!/usr/bin/env bash
# Checks a bundle made by deploy/bundle.sh the way a machine without our packages would use it:
#   deploy/check-bundle.sh TARBALL
# 1. unpacks it into an empty temporary folder;
# 2. `ldd` on every program and library: nothing may resolve outside the bundle except glibc's
#    own libraries, and nothing may be missing;
# 3. runs from there under `env -i PATH=/usr/bin:/bin` (no LD_LIBRARY_PATH, no HOME, no VK_*;
#    the Vulkan driver is the host's, here lavapipe from the system's icd.d):
#    --list-devices, irradcast-bake on cornell with the Embree and the Vulkan backend (exit 0,
#    view.png, view.exr, lightmaps, report.json), a server with a viewer on loopback (the view
#    written, the server stopped by SIGTERM exits 0), and checks in the server's memory map that
#    every library the bundle has was loaded from the bundle.
# About 20 s on the 2-core VM.
set -euo pipefail
[ $# -eq 1 ] && [ -f "$1" ] || {
  echo "usage: deploy/check-bundle.sh TARBALL" >&2
  exit 2
}
tarball=$(cd "$(dirname "$1")" && pwd)/$(basename "$1")
tmp=$(mktemp -d /tmp/irradcast-check-bundle.XXXXXX)
server_pid=
cleanup() {
  if [ -n "$server_pid" ]; then kill "$server_pid" 2>/dev/null || true; fi
  rm -rf "$tmp"
}
trap cleanup EXIT
fail() {
  echo "check-bundle: FAIL: $*" >&2
  exit 1
}
step() { echo "check-bundle: $* (${SECONDS} s)"; }

tar -C "$tmp" -xzf "$tarball"
root=$(find "$tmp" -mindepth 1 -maxdepth 1 -type d)
[ "$(wc -l <<<"$root")" = 1 ] && [ -d "$root/bin" ] && [ -d "$root/lib" ] ||
  fail "$tarball does not hold one bundle folder with bin/ and lib/"
cd "$root"
step "unpacked $(basename "$tarball") into $root"

# 2. ldd: every dependency inside the bundle, or glibc's.
glibc='^(linux-vdso\.so|ld-linux[^ ]*\.so|libc\.so|libm\.so|libmvec\.so|libpthread\.so|libdl\.so|librt\.so|libutil\.so|libresolv\.so|libanl\.so)'
files=0
for f in bin/* lib/*; do
  files=$((files + 1))
  while read -r soname arrow path rest; do
    case "$soname" in statically | not) continue ;; esac
    if [ "$arrow" = "=>" ] && [ "$path" = not ]; then fail "ldd $f: $soname not found"; fi
    [[ "$soname" =~ $glibc ]] && continue
    [[ "$soname" == /* ]] && continue # the interpreter line of ld-linux
    path=$(readlink -f "$path")
    [[ "$path" == "$root"/lib/* ]] || fail "ldd $f: $soname resolves outside the bundle: $path"
  done < <(ldd "$f")
done
step "ldd: $files files, nothing outside the bundle but glibc"

run() { env -i PATH=/usr/bin:/bin "$@"; }
out=$tmp/run
mkdir -p "$out"

devices=$(run bin/irradcast-server --list-devices 2>&1) || fail "--list-devices: $devices"
grep -q '^embree: the CPU' <<<"$devices" || fail "--list-devices names no Embree: $devices"
grep -q '^vulkan: \[0\]' <<<"$devices" || fail "--list-devices finds no Vulkan device: $devices"
step "--list-devices: $(grep '^vulkan: \[0\]' <<<"$devices")"

bake() {
  local backend=$1 dir=$out/bake-$1 log
  log=$(run bin/irradcast-bake --scene cornell --updates 2 --texels-per-scene 24 --width 64 \
    --height 48 --backend "$backend" --out "$dir" 2>&1) || fail "bake --backend $backend: $log"
  grep -q "backend: $backend" <<<"$log" || fail "bake --backend $backend ran elsewhere: $log"
  for f in view.png view.exr report.json; do
    [ -s "$dir/$f" ] || fail "bake --backend $backend wrote no $f"
  done
  [ -n "$(ls "$dir/lightmaps")" ] || fail "bake --backend $backend wrote no lightmaps"
  step "bake --scene cornell --backend $backend: $(ls "$dir/lightmaps" | wc -l) lightmaps, view.png"
}
bake embree
bake vulkan

# A server and a viewer on loopback; the port is the one the server logs. (env execs the
# server: $! is its pid.)
env -i PATH=/usr/bin:/bin bin/irradcast-server --scene cornell --bind 127.0.0.1 --port 0 --texels-per-scene 24 \
  --max-updates 4 --status-every 0 >"$out/server.log" 2>&1 &
server_pid=$!
port=
for _ in $(seq 100); do
  port=$(sed -n 's/.*listening on 127\.0\.0\.1:\([0-9][0-9]*\).*/\1/p' "$out/server.log")
  [ -n "$port" ] && break
  kill -0 "$server_pid" 2>/dev/null || fail "the server exited: $(cat "$out/server.log")"
  sleep 0.1
done
[ -n "$port" ] || fail "the server did not say its port: $(cat "$out/server.log")"
view=$(run bin/irradcast-view --connect "127.0.0.1:$port" --out "$out/view.png" --width 64 \
  --height 48 --until-converged --timeout 20 --cache-dir none 2>&1) || fail "viewer: $view"
[ -s "$out/view.png" ] || fail "the viewer wrote no view.png: $view"
# Every library of the bundle that the running server loaded came from the bundle.
loaded=0
while read -r path; do
  base=$(basename "$path")
  [ -e "lib/$base" ] || continue
  [ "$path" = "$root/lib/$base" ] || fail "the server loaded $base from $path"
  loaded=$((loaded + 1))
done < <(awk '$6 ~ /\.so/ {print $6}' "/proc/$server_pid/maps" | sort -u)
[ "$loaded" -ge 10 ] || fail "the server loaded only $loaded of the bundle's libraries"
kill -TERM "$server_pid"
status=0
wait "$server_pid" || status=$?
server_pid=
[ "$status" = 0 ] || fail "the server exited $status after SIGTERM: $(tail -5 "$out/server.log")"
step "server on 127.0.0.1:$port ($loaded libraries loaded, all from the bundle) + viewer: view.png, server exit 0 after SIGTERM"
echo "check-bundle: OK in ${SECONDS} s"
