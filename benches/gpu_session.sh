#!/usr/bin/env bash
# One call on a lent GPU, prepared on a machine without one.
#
# A session is lent a GPU for about fifteen minutes, its start included, and
# the machine reaches nothing outside it (no crates, no pip). So everything
# is built here and carried in one archive, and one command measures all
# that is waiting for a GPU: the frames at real sizes profiled pass by pass
# (the real-time issue's first step on a device) and each experiment kept
# under docs/experiments/ that was slower or unmeasurable on lavapipe, its
# binary alternated with the build it changes.
#
#   bash benches/gpu_session.sh pack    # here: builds target/gpu-kit.tar.xz
#   # then, with the device tool, carrying target/gpu-kit.tar.xz:
#   bash benches/gpu_session.sh run     # there: writes $OUT/
#
# `pack` needs a clean work tree (it applies each experiment's patch in
# place, builds, and takes the patch out again), the release build's
# dependencies, and OIDN from the `pyoidn` package (FILTERJIT_OIDN or
# /tmp/venv). `run` works on any Vulkan adapter, lavapipe included, which
# is how it is tested: `FILTERJIT_GPU_SESSION_QUICK=1` runs it at 256²
# with one repeat.
set -euo pipefail

# The experiments a GPU decides, each a patch under docs/experiments/ that
# applies to the commit the kit is built at (tests/readme.rs checks that
# each still applies: rebase it or drop it here); each is timed on the
# filters whose kernels it changes.
EXPERIMENTS=(
    "temporal-packed-stores:@realtimeTemporal @temporal"
    "one-band-per-pass:@realtime @evolvedAtrous64Plane"
    "trusted-built-ins:@realtime @realtimeTemporal"
)
# The frames of the real-time issue: the shipped filters at 1080p and 1440p.
FILTERS=(@realtime @realtimeTemporal @evolvedAtrous64Plane @temporal @evolvedAtrous3x3)

root=$(cd "$(dirname "$0")/.." && pwd)
kit_archive="$root/target/gpu-kit.tar.xz"

pack() {
    cd "$root"
    if [ -n "$(git status --porcelain --untracked-files=no)" ]; then
        echo "gpu_session pack: the work tree has changes; commit or stash them first" >&2
        exit 1
    fi
    local oidn="${FILTERJIT_OIDN:-/tmp/venv/lib/python3.11/site-packages/pyoidn/oidn/bin/oidnDenoise}"
    if [ ! -x "$oidn" ]; then
        echo "gpu_session pack: no oidnDenoise at $oidn (set FILTERJIT_OIDN, or pip install pyoidn into /tmp/venv)" >&2
        exit 1
    fi
    local kit="$root/target/gpu-kit"
    rm -rf "$kit" && mkdir -p "$kit/bin" "$kit/lib"
    for experiment in "${EXPERIMENTS[@]}"; do
        local name=${experiment%%:*}
        patch="docs/experiments/$name.patch"
        git apply "$patch"
        # Takes the patch out again if its build fails half-way.
        trap 'git -C "$root" apply -R "$patch"' EXIT
        cargo build --release --quiet
        strip -o "$kit/bin/filterjit-$name" target/release/filterjit
        git apply -R "$patch"
        trap - EXIT
    done
    cargo build --release --quiet
    strip -o "$kit/bin/filterjit" target/release/filterjit
    git rev-parse HEAD > "$kit/commit"
    # OIDN's command, its core, its CPU and CUDA devices and TBB; the loader
    # finds the devices beside the core.
    cp "$oidn" "$kit/bin/"
    local lib
    lib=$(dirname "$oidn")/../lib
    cp -L "$lib"/libOpenImageDenoise.so.2 "$lib"/libOpenImageDenoise_core.so.2.5.1 \
        "$lib"/libOpenImageDenoise_device_cpu.so.2.5.1 "$lib"/libOpenImageDenoise_device_cuda.so.2.5.1 \
        "$lib"/libtbb.so.12 "$kit/lib/"
    # The Vulkan loader: the device's image has the driver's ICD, not always the loader.
    cp -L /lib/x86_64-linux-gnu/libvulkan.so.1 "$kit/lib/"
    # One thread and a dictionary wider than a binary: the builds differ in a
    # few kernels, so each after the first packs into almost nothing.
    tar -C "$root/target" -cf - gpu-kit | xz -T1 --lzma2=preset=6,dict=64MiB > "$kit_archive.tmp"
    mv "$kit_archive.tmp" "$kit_archive"
    echo "gpu_session pack: $(du -h "$kit_archive" | cut -f1) in $kit_archive (carry it; 64 MiB at most)"
}

# step NAME COMMAND...: runs COMMAND into $out/NAME.txt; a step that fails
# says so and the run goes on, since the device's minutes are not repeated.
step() {
    local log="$out/$1.txt"
    shift
    if ! "$@" > "$log" 2>&1; then
        echo "gpu_session run: $(basename "$log") failed:"
        tail -5 "$log"
    fi
}

run() {
    out="${OUT:?gpu_session run: OUT names the folder the results go to}"
    local quick="${FILTERJIT_GPU_SESSION_QUICK:-}"
    local kit
    kit=$(mktemp -d)
    # The device's image may lack xz; Python's lzma reads the same archive.
    if command -v xz > /dev/null; then
        xz -dc "$kit_archive" | tar -C "$kit" -xf -
    else
        python3 -c 'import sys, tarfile; tarfile.open(sys.argv[1], "r:xz").extractall(sys.argv[2])' "$kit_archive" "$kit"
    fi
    kit="$kit/gpu-kit"
    export LD_LIBRARY_PATH="$kit/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
    export FILTERJIT_OIDN="$kit/bin/oidnDenoise"
    # The driver's own shader cache would hide compile costs and carry state between builds.
    export __GL_SHADER_DISK_CACHE=0 MESA_SHADER_CACHE_DISABLE=true
    local sizes=1920x1080,2560x1440 repeats=10 profile_repeats=5
    if [ -n "$quick" ]; then sizes=256x256 repeats=1 profile_repeats=1; fi
    cp "$kit/commit" "$out/commit"
    { nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm,power.draw --format=csv 2>&1 || true; } > "$out/gpu.txt"
    local filters=()
    for f in "${FILTERS[@]}"; do filters+=(--filter "$f"); done
    # 1. The frames with OIDN (CUDA where found), then where each goes, pass by pass.
    step frames "$kit/bin/filterjit" bench --frames "$sizes" --repeats "$repeats" "${filters[@]}" -o "$out/frames.json"
    step profile "$kit/bin/filterjit" bench --frames "${sizes%%,*}" --repeats "$profile_repeats" --no-oidn --profile \
        "${filters[@]}" -o "$out/profile.json"
    # 2. Each experiment against the build it changes, alternated twice.
    for experiment in "${EXPERIMENTS[@]}"; do
        local name=${experiment%%:*} its=()
        for f in ${experiment#*:}; do its+=(--filter "$f"); done
        for round in 1 2; do
            for build in filterjit "filterjit-$name"; do
                step "$name-$build-$round" "$kit/bin/$build" bench --frames "${sizes%%,*}" \
                    --repeats "$profile_repeats" --no-oidn --profile "${its[@]}" -o "$out/$name-$build-$round.json"
            done
        done
    done
    tail -25 "$out/frames.txt"
    # Each experiment's frames beside its base build's, for the reply's tail.
    for f in "$out"/*-[12].txt; do
        echo "$(basename "$f" .txt): $(grep '^profile' "$f" | sed 's/: each kernel.*frames)://; s/ (the rest[^)]*)//' | tr '\n' ';')"
    done
    echo "gpu_session run: results in $out"
}

case "${1:-}" in
    pack) pack ;;
    run) run ;;
    *)
        echo "usage: bash benches/gpu_session.sh pack|run (see the comment at its top)" >&2
        exit 2
        ;;
esac
