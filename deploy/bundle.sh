#!/usr/bin/env bash
# Makes a relocatable bundle of irradcast's programs: OUT_DIR/irradcast-bundle-<hash>-x86_64/
# (bin/, lib/, share/) and OUT_DIR/irradcast-bundle-<hash>-x86_64.tar.gz, to run on a Linux
# x86-64 machine without Debian or our packages (docs/DEPLOY.md).
#   deploy/bundle.sh OUT_DIR [BUILD_DIR]
# BUILD_DIR: an existing build tree whose programs are bundled (irradcast-server, -bake, -view,
# -load, -edit; irradcast-gateway, irradcast-bench-backend and irradcast_tests when it has them).
# Without it, a Release tree build-bundle/ is configured (tests and benches on) and only those
# targets are built.
# The programs are stripped; every shared library they load except glibc's own (libc, libm,
# libpthread, libdl, librt, ld-linux, ...) is copied into lib/ and found through an
# $ORIGIN-relative DT_RPATH (patchelf): bin/ -> $ORIGIN/../lib, lib/ -> $ORIGIN. DT_RPATH, not
# DT_RUNPATH: it is searched before LD_LIBRARY_PATH and for the libraries' own dependencies, so a
# host's libraries never replace the bundle's. Also bundled: libtbbmalloc (TBB dlopens it beside
# libtbb), the Vulkan loader libvulkan.so.1 (a GPU machine may have a driver but no loader) and,
# when installed here, the Khronos validation layer with its manifest (share/vulkan/
# explicit_layer.d; VK_ADD_LAYER_PATH names it; the parity tests need it). No Vulkan driver is
# bundled: the loader finds the host's through VK_DRIVER_FILES or the system's icd.d folders.
# The shaders are SPIR-V compiled into the programs (server/engine/CMakeLists.txt): no files.
# Fails when the tarball exceeds IRRADCAST_BUNDLE_MAX_MIB (60).
set -euo pipefail
src=$(cd "$(dirname "$0")/.." && pwd)
[ $# -ge 1 ] && [ $# -le 2 ] || {
  echo "usage: deploy/bundle.sh OUT_DIR [BUILD_DIR]" >&2
  exit 2
}
out=$1
build=${2:-}
max_mib=${IRRADCAST_BUNDLE_MAX_MIB:-60}
for tool in patchelf strip ldd tar gzip; do
  command -v "$tool" >/dev/null || {
    echo "bundle: $tool is missing (deploy/install-deps.sh)" >&2
    exit 1
  }
done
[ "$(uname -m)" = x86_64 ] || {
  echo "bundle: this machine is $(uname -m), the bundle is x86_64 only" >&2
  exit 1
}

required=(irradcast-server irradcast-bake irradcast-view irradcast-load irradcast-edit)
optional=(irradcast-gateway irradcast-bench-backend irradcast_tests)

if [ -z "$build" ]; then
  build=$src/build-bundle
  launcher=()
  if command -v ccache >/dev/null; then
    launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
  fi
  generator=()
  if [ ! -f "$build/CMakeCache.txt" ] && command -v ninja >/dev/null; then generator=(-G Ninja); fi
  cmake -S "$src" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release \
    -DIRRADCAST_BUILD_TESTS=ON -DIRRADCAST_BUILD_BENCH=ON "${launcher[@]}" >/dev/null
fi
build=$(cd "$build" && pwd)
# The optional programs this tree has as targets (a stale binary of an earlier configuration,
# tests since turned off say, is not bundled).
known=$(cmake --build "$build" --target help)
targets=("${required[@]}")
for t in "${optional[@]}"; do
  if grep -Eq "(^|\.\.\. )$t(:| |\$)" <<<"$known"; then targets+=("$t"); fi
done
if [ -z "${2:-}" ]; then
  cmake --build "$build" --parallel "$(nproc)" --target "${targets[@]}"
fi

hash=$(git -C "$src" rev-parse --short HEAD 2>/dev/null || echo unknown)
name=irradcast-bundle-$hash-x86_64
mkdir -p "$out"
out=$(cd "$out" && pwd)
stage=$out/$name
rm -rf "$stage" "$stage.tar.gz"
mkdir -p "$stage/bin" "$stage/lib" "$stage/share/vulkan/explicit_layer.d"

# The build tree's program NAME (the newest, should a stale copy linger elsewhere).
find_program() {
  find "$build" -maxdepth 3 -type f -name "$1" -perm -u+x -printf '%T@ %p\n' 2>/dev/null |
    sort -rn | head -n 1 | cut -d' ' -f2-
}

programs=()
for p in "${targets[@]}"; do
  path=$(find_program "$p")
  if [ -z "$path" ]; then
    for r in "${required[@]}"; do
      [ "$r" != "$p" ] || {
        echo "bundle: $p is not built in $build" >&2
        exit 1
      }
    done
    continue
  fi
  cp "$path" "$stage/bin/$p"
  programs+=("$p")
done

# glibc's own libraries: left to the host (they must match its ld-linux).
is_glibc() {
  case "$1" in
  linux-vdso.so.* | ld-linux*.so.* | libc.so.* | libm.so.* | libmvec.so.* | libpthread.so.* | \
    libdl.so.* | librt.so.* | libutil.so.* | libresolv.so.* | libanl.so.* | libnsl.so.* | \
    libBrokenLocale.so.*) return 0 ;;
  esac
  return 1
}

# Copies a library (the file a symlink points to, under the name asked for) into lib/ once.
add_library() {
  local soname=$1 path=$2
  [ -e "$stage/lib/$soname" ] && return 0
  cp -L "$path" "$stage/lib/$soname"
  chmod u+w "$stage/lib/$soname"
}

# Every library the ELF files given need, as this machine's loader resolves them (the closure).
add_dependencies() {
  local f soname arrow path rest
  for f in "$@"; do
    while read -r soname arrow path rest; do
      [ "$arrow" = "=>" ] || continue
      is_glibc "$soname" && continue
      [ "$path" != "not" ] || {
        echo "bundle: $f: $soname not found" >&2
        exit 1
      }
      add_library "$soname" "$path"
    done < <(ldd "$f")
  done
}

libdir_of() { dirname "$(readlink -f "$(ldd "$stage/bin/irradcast-server" | awk -v l="$1" '$1 == l {print $3}')")"; }

add_dependencies "$stage"/bin/*
# TBB dlopens its allocator from its own folder; missing, it falls back to malloc silently.
tbbdir=$(libdir_of libtbb.so.12)
[ -e "$tbbdir/libtbbmalloc.so.2" ] && add_library libtbbmalloc.so.2 "$tbbdir/libtbbmalloc.so.2"
# The validation layer (optional: only --vulkan-validation runs and the tests load it).
layer_json=/usr/share/vulkan/explicit_layer.d/VkLayer_khronos_validation.json
layer_lib=$(libdir_of libvulkan.so.1)/libVkLayer_khronos_validation.so
if [ "${IRRADCAST_BUNDLE_VALIDATION:-1}" = 1 ] && [ -f "$layer_json" ] && [ -f "$layer_lib" ]; then
  add_library libVkLayer_khronos_validation.so "$layer_lib"
  # A library_path with a slash is relative to the manifest's folder.
  sed 's#"library_path": *"[^"]*"#"library_path": "../../../lib/libVkLayer_khronos_validation.so"#' \
    "$layer_json" >"$stage/share/vulkan/explicit_layer.d/VkLayer_khronos_validation.json"
fi
add_dependencies "$stage"/lib/*

for f in "$stage"/bin/*; do
  strip --strip-all "$f"
  patchelf --force-rpath --set-rpath '$ORIGIN/../lib' "$f"
done
for f in "$stage"/lib/*; do
  strip --strip-unneeded "$f"
  patchelf --force-rpath --set-rpath '$ORIGIN' "$f"
done

# The newest glibc symbol version anything in the bundle asks for: the host needs at least that.
glibc=$(for f in "$stage"/bin/* "$stage"/lib/*; do objdump -T "$f"; done |
  grep -o 'GLIBC_[0-9][0-9.]*' | sort -u -t_ -k2,2V | tail -n 1 | cut -d_ -f2)
{
  echo "irradcast bundle $name"
  echo "commit: $(git -C "$src" rev-parse HEAD 2>/dev/null || echo unknown)$(git -C "$src" diff --quiet HEAD 2>/dev/null || echo ' (with uncommitted changes)')"
  echo "built: $(date -u +%Y-%m-%dT%H:%M:%SZ) on $(. /etc/os-release && echo "$PRETTY_NAME"), build type $(sed -n 's/^CMAKE_BUILD_TYPE:STRING=//p' "$build/CMakeCache.txt")"
  echo "needs on the host: Linux x86-64, glibc >= $glibc, a Vulkan driver for --backend vulkan (VK_DRIVER_FILES=.../icd.json)"
  echo "programs: ${programs[*]}"
  echo "libraries: $(cd "$stage/lib" && ls | tr '\n' ' ')"
  echo "validation layer: export VK_ADD_LAYER_PATH=\$BUNDLE/share/vulkan/explicit_layer.d"
  echo "docs: docs/DEPLOY.md of the irradcast sources"
} >"$stage/BUNDLE.txt"
[ -n "$(ls "$stage/share/vulkan/explicit_layer.d")" ] || rm -r "$stage/share"

tar -C "$out" -czf "$stage.tar.gz" "$name"
bytes=$(stat -c %s "$stage.tar.gz")
unpacked=$(du -sb "$stage" | cut -f1)
mib() { awk -v b="$1" 'BEGIN { printf "%.1f", b / 1048576 }'; }
echo "bundle: $stage.tar.gz: $(mib "$bytes") MiB ($(mib "$unpacked") MiB unpacked), ${#programs[@]} programs, $(ls "$stage/lib" | wc -l) libraries, glibc >= $glibc"
if [ "$bytes" -gt $((max_mib * 1048576)) ]; then
  echo "bundle: the tarball exceeds $max_mib MiB" >&2
  exit 1
fi
