#!/bin/bash
# gpu_device.sh: scripts/gpu_check.py on a GPU machine whose Python has no
# mitsuba (a lent device with no network, docs/jit.md "CUDA").
#
#   bash scripts/gpu_device.sh pack        # here, after `make plugin`
#   bash scripts/gpu_device.sh run [ARGS]  # there, from the checkout's root
#
# pack downloads the pinned mitsuba and drjit wheels for that machine's Python
# (GPU_PYTHON, default 3.12), keeps what the checks load (the rgb and spectral
# variants, the plugins the scenes use) and writes .gpu/site.tar.xz (~31 MB).
# Send the checkout with .gpu, build/plugins and target/release/libstam.so.
# run unpacks it to /tmp/site and runs gpu_check.py in cuda_ad_rgb and
# cuda_ad_spectral (ARGS go to both, e.g. --checks accuracy,chi2), writing
# each log to $OUT (default out/gpu).
set -euo pipefail
cd "$(dirname "$0")/.."
here=.gpu

pack() {
    local py=${GPU_PYTHON:-3.12} req=scripts/requirements.txt
    local mi dr
    mi=$(grep -E '^mitsuba==' $req)
    dr=$(grep -E '^drjit==' $req)
    rm -rf $here/wheels $here/site && mkdir -p $here/wheels $here/site
    python3 -m pip download -q --no-deps --only-binary=:all: --python-version "$py" \
        --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 \
        --platform manylinux_2_17_x86_64 -d $here/wheels "$mi" "$dr"
    for w in $here/wheels/*.whl; do (cd $here/site && python3 -m zipfile -e "../../$w" .); done
    # What the checks never load: other variants, headers, unused plugins.
    (cd $here/site/mitsuba && rm -rf include cmake pkgconfig mitsuba_stubs \
        ./*polarized*.so llvm_ad_*.so cuda_ad_mono*.so \
        plugins/{ellipsoids,ellipsoidsmesh,volpathmis,bsplinecurve,sdfgrid,sunsky,timed_sunsky,ptracer}.so)
    rm -rf $here/site/drjit/include $here/site/drjit/cmake
    tar -C $here/site -cJf $here/site.tar.xz .
    rm -rf $here/wheels $here/site
    ls -l $here/site.tar.xz
}

run() {
    local out=${OUT:-out/gpu}
    mkdir -p "$out" /tmp/site
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader || true
    tar -C /tmp/site -xJf $here/site.tar.xz
    export PYTHONPATH=/tmp/site${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1
    export DRJIT_CACHE_DIR=${DRJIT_CACHE_DIR:-/tmp/drjit-cache}
    local status=0 v
    # The height-map case's map (numpy only; seconds)
    [ -e scenes/heightmaps/gaussian.npy ] ||
        python3 scripts/make_heightmaps.py --out scenes/heightmaps > /dev/null || true
    for v in cuda_ad_rgb cuda_ad_spectral; do
        python3 scripts/gpu_check.py --variant $v "$@" > "$out/$v.log" 2>&1 || status=1
        grep -E '^\[gpu_check\]|Error|Traceback' "$out/$v.log" || true
    done
    return $status
}

case "${1:-}" in
    pack) pack ;;
    run) shift; run "$@" ;;
    *) sed -n '2,15p' "$0"; exit 2 ;;
esac
