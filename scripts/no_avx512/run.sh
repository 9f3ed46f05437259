#!/usr/bin/env bash
# Run a command as it runs on an x86-64 CPU without AVX-512 (AVX2 and FMA only), natively.
#   scripts/no_avx512/run.sh .venv/bin/python -m pytest -q
#   scripts/no_avx512/run.sh .venv/bin/python -m pressor synth --out x.npz
# Needs Linux with CPUID faulting (the `cpuid_fault` flag in /proc/cpuinfo) and a C compiler;
# how it works and its limits: no_avx512.c and docs/PLATFORM-NOTES.md.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
lib="${TMPDIR:-/tmp}/pressor-no_avx512-$(id -u).so"
tmp="$(mktemp "$lib.XXXXXX")"
"${CC:-cc}" -O2 -Wall -shared -fPIC -o "$tmp" "$here/no_avx512.c" -ldl
mv -f "$tmp" "$lib"
# glibc picks its string and memory kernels before the preload runs: hold it back by tunables.
export GLIBC_TUNABLES="glibc.cpu.hwcaps=-AVX512F,-AVX512DQ,-AVX512BW,-AVX512VL,-AVX512CD,-AVX512ER,-AVX512PF"
export LD_PRELOAD="$lib${LD_PRELOAD:+:$LD_PRELOAD}"
exec "$@"
