#!/usr/bin/env bash
# Installs what dispflow-vk needs to build and test, then links shaderc for build.rs.
# Idempotent: when everything is present it only checks and exits in about a second.
#
#   bash tools/setup.sh          # install (Debian/Ubuntu; uses sudo when not root)
#   bash tools/setup.sh --check  # only report what is missing
#
# System packages (Debian 12 / Ubuntu 22.04+ names):
#   mesa-vulkan-drivers      Vulkan loader + Mesa lavapipe (CPU Vulkan driver, used by the tests)
#   vulkan-validationlayers  Khronos validation layer (tests fail on any validation error)
#   libshaderc-dev           shaderc + glslang + SPIRV-Tools static libraries (GLSL -> SPIR-V in build.rs)
#   build-essential          C/C++ toolchain and `ar`
#   slurmctld slurmd slurm-client munge
#                            Slurm 22.05 and munge, for `sweep --slurm` and its test against real
#                            daemons (tools/slurm_local.sh starts a one-node cluster, no systemd)
# Other systems: install the Vulkan loader, a Vulkan driver (lavapipe works), the Khronos validation
# layer and shaderc's static libraries, then point SHADERC_LIB_DIR at a directory holding a
# self-contained libshaderc_combined.a (or enable the shaderc crate's `build-from-source` feature).
set -euo pipefail
cd "$(dirname "$0")/.."

check_only=0
[ "${1:-}" = "--check" ] && check_only=1

pkgs=(mesa-vulkan-drivers vulkan-validationlayers libshaderc-dev build-essential slurmctld slurmd slurm-client munge)
missing=()
if command -v dpkg-query >/dev/null 2>&1; then
  for p in "${pkgs[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
else
  echo "setup: not a Debian/Ubuntu system; install the equivalents of: ${pkgs[*]}" >&2
fi

if [ ${#missing[@]} -gt 0 ]; then
  if [ $check_only = 1 ]; then
    echo "setup: missing packages: ${missing[*]}" >&2
    exit 1
  fi
  sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  echo "setup: installing ${missing[*]}"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# Debian's libshaderc_combined.a holds shaderc alone and libshaderc.so leaves glslang symbols
# undefined, so shaderc-sys cannot link either as shipped. Merge the static archives into one
# self-contained libshaderc_combined.a under .deps/shaderc (SHADERC_LIB_DIR in .cargo/config.toml).
libdir=""
for d in /usr/lib/x86_64-linux-gnu /usr/lib/aarch64-linux-gnu /usr/lib64 /usr/lib; do
  [ -f "$d/libshaderc_combined.a" ] && { libdir=$d; break; }
done
if [ -z "$libdir" ]; then
  echo "setup: libshaderc_combined.a not found; install the package libshaderc-dev" >&2
  exit 1
fi
out=.deps/shaderc
merged=$out/libshaderc_combined.a
parts=(shaderc_combined glslang MachineIndependent OSDependent GenericCodeGen OGLCompiler HLSL SPIRV SPIRV-Tools-opt SPIRV-Tools)
newest=0
for p in "${parts[@]}"; do
  [ -f "$libdir/lib$p.a" ] || continue
  t=$(stat -c %Y "$libdir/lib$p.a"); [ "$t" -gt "$newest" ] && newest=$t
done
if [ ! -f "$merged" ] || [ "$(stat -c %Y "$merged")" -lt "$newest" ]; then
  [ $check_only = 1 ] && { echo "setup: $merged is missing or stale" >&2; exit 1; }
  mkdir -p "$out"
  script="CREATE $merged.tmp"
  for p in "${parts[@]}"; do
    [ -f "$libdir/lib$p.a" ] && script+=$'\n'"ADDLIB $libdir/lib$p.a"
  done
  script+=$'\nSAVE\nEND'
  rm -f "$merged.tmp"
  printf '%s\n' "$script" | ar -M
  ranlib "$merged.tmp"
  mv "$merged.tmp" "$merged"
  echo "setup: wrote $merged (from $libdir)"
  # shaderc-sys caches the search result: make it look again.
  if [ -d target ] && command -v cargo >/dev/null 2>&1; then cargo clean -q -p shaderc-sys 2>/dev/null || true; fi
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "setup: cargo not found; install Rust (https://rustup.rs) and re-run" >&2
  exit 1
fi
echo "setup: ok"
