#!/usr/bin/env bash
# One lent GPU machine (the device tool; NVIDIA, no network): install what glradial needs from carried
# wheels and Debian packages, then `bench` (the GPU figures of docs/BENCH.md), `train [SECONDS]` (stage 12,
# net/configs/stage12_multitask.json, from the shipped weights: one call trains SECONDS more of step time,
# default 420, in the foreground, logged to runs/stage12/log.txt; call it again until the log says "done")
# or `finish` (export + evaluation of the best checkpoint, error-head calibration).
# Usage from the repository root there: bash scripts/device_session.sh bench|train [SECONDS]|finish
# Each train call copies last.pt/best.pt/train.csv to $OUT, so a run can continue on a fresh machine:
# carry runs/stage12 (and data_cache is re-rendered; about a minute on a GPU).
set -uo pipefail
OUT=${OUT:-out/device}
mkdir -p "$OUT"
if [ ! -e /tmp/site/.done ]; then
  for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl && touch /tmp/site/.done
fi
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
export __EGL_VENDOR_LIBRARY_FILENAMES=${__EGL_VENDOR_LIBRARY_FILENAMES:-/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json}
case "$1" in
  bench)
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv | tee "$OUT/gpu.txt"
    python3 -c 'from glradial import egl; print("GL renderer:", egl.renderer_name(egl.thread_context()))' 2>&1 | tee -a "$OUT/gpu.txt"
    for b in "bench_correct.py --frames 60" "bench_crops.py --rounds 5" "bench_stadium.py --full" \
             "bench_estimate.py --frames 30 --pitch glradial/data/usl_broadcast_0195.jpg"; do
      echo "== python3 bench/$b" | tee -a "$OUT/bench.txt"
      timeout 150 python3 bench/$b 2>&1 | tee -a "$OUT/bench.txt"
    done ;;
  train)
    RUN=runs/stage12
    mkdir -p $RUN
    if [ ! -e data_cache/.stage12 ]; then  # the panoramas (cached; kept while the machine stays warm)
      python3 -m net.data --split train --n 80 --split val --n 4 --split test --n 8 --size 4096 2048 > "$OUT/data.txt" 2>&1 \
        && touch data_cache/.stage12
      tail -3 "$OUT/data.txt"
    fi
    [ -e runs/shipped_from_onnx.pt ] || python3 -m net.from_onnx --onnx glradial/models/glradial_k1k2.onnx \
      --out runs/shipped_from_onnx.pt 2>&1 | tail -1
    # in the foreground: a machine left idle between calls is given back with the run on it
    python3 -m net.train --config net/configs/stage12_multitask.json --out $RUN --init runs/shipped_from_onnx.pt \
      --resume --stop-after-s "${2:-420}" >> $RUN/log.txt 2>&1 < /dev/null
    tail -5 $RUN/log.txt
    cp $RUN/last.pt $RUN/best.pt $RUN/train.csv $RUN/log.txt "$OUT/" 2>/dev/null ;;
  finish)
    RUN=runs/stage12
    while pgrep -f "net.train" > /dev/null; do sleep 5; done
    tail -4 $RUN/log.txt
    python3 -m net.export --checkpoint $RUN/best.pt --out $RUN/model.onnx 2>&1 | tail -2
    cp $RUN/log.txt $RUN/train.csv $RUN/best.pt $RUN/model.onnx "$OUT/" 2>/dev/null
    for m in glradial/models/glradial_k1k2.onnx $RUN/model.onnx; do
      n=$(basename $(dirname $m)); python3 -m glradial evaluate --model $m --out /tmp/eval_$n -q --threads 16 2>&1 | tail -3
      cp /tmp/eval_$n/metrics.json $OUT/eval_$n.json
    done
    python3 -m net.error_calibration --model $RUN/model.onnx --split val --out $OUT/val_errors.npz
    python3 -m net.error_calibration --model $RUN/model.onnx --split test --panoramas 8 --out $OUT/test_errors.npz ;;
  *)
    echo "usage: bash scripts/device_session.sh bench|train [SECONDS]|finish" >&2; exit 2 ;;
esac
