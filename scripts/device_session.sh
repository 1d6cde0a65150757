#!/usr/bin/env bash
# A lent GPU machine (the device tool; NVIDIA H100/H200, no network). Subcommands:
#
#   wheels    HERE, before the session (needs the package registries, not a GPU): the wheels and
#             Debian packages the machine lacks, into .whl/ and .gl/ (git-ignored; name both in `carry`).
#   session   THERE, the whole lent session in ONE call of at most 9 minutes (run it first):
#             install, GPU check, 200 + 12 stadium panoramas, a 30 s throughput check of the GPU batch
#             source (bench/bench_train_throughput.py), TRAIN_S (270) seconds of training with it
#             (net/configs/stage13_gpu_source.json) from the checkpoint to continue from, ONNX export
#             with metadata, evaluation against the shipped model (python -m net.compare), and the
#             new checkpoint to continue from. Everything lands in $OUT (at most 8 files):
#               session.log (all output), throughput.txt, train.csv, model.onnx, continue.pt
#             The next session commits continue.pt as net/checkpoints/continue.pt (EMA weights only,
#             5.5 MB; the one committed first is the shipped model, rebuilt by net.from_onnx) and
#             starts from it; without the file it rebuilds the shipped model first (about a minute).
#   bench     THERE: the GL/GPU figures of docs/BENCH.md (correct, crops, stadium, estimate).
#   train [S] / finish   THERE: stage 12 (pool source) in resumable calls, then its export and evaluation.
#
# Tool call for `session` (from the repository root here, after `bash scripts/device_session.sh wheels`):
#   run(command="bash scripts/device_session.sh session", carry=[".whl", ".gl"], timeout_s=600)
# SMOKE=1 runs `session` on this CPU with tiny sizes (no install, tiny network, synthetic stadium
# counts, a few seconds of training), to check the script before a GPU is lent.
set -uo pipefail
OUT=${OUT:-out/device}
mkdir -p "$OUT"
SMOKE=${SMOKE:-0}
PY=${PY:-python3}

install_there() {
  if [ "$SMOKE" = 1 ]; then return; fi
  if [ ! -e /tmp/site/.done ]; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
    $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
      && touch /tmp/site/.done
  fi
  export PYTHONPATH=/tmp/site:$PWD
  export __EGL_VENDOR_LIBRARY_FILENAMES=${__EGL_VENDOR_LIBRARY_FILENAMES:-/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json}
}
export PYTHONPATH=${PYTHONPATH:-$PWD} PYTHONUNBUFFERED=1

wheels() {  # here: what the machine's image lacks (KINDS.md: it has torch, numpy, OpenCV, onnx, onnxruntime, scipy)
  mkdir -p .whl .gl /tmp/amd64/partial
  python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
    -d .whl moderngl glcontext
  o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
  apt-get $o update -qq && (cd .gl && apt-get $o download libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
  ls -la .whl .gl
}

session() {
  local t0=$SECONDS RUN=runs/stage13 CONFIG=net/configs/stage13_gpu_source.json TRAIN_S=${TRAIN_S:-270}
  local NTRAIN=200 SIZE="4096 2048" BENCH_S=8 NVAL=800 NTEST=8 INIT=net/checkpoints/continue.pt EXTRA=()
  local REF=glradial/models/glradial_k1k2.onnx
  if [ "$SMOKE" = 1 ]; then  # this CPU: a tiny network on a few small synthetic-size stadiums
    CONFIG=$OUT/smoke.json TRAIN_S=${TRAIN_S_SMOKE:-4} NTRAIN=2 SIZE="512 256" BENCH_S=1 NVAL=16 NTEST=1 INIT= REF=$OUT/model.onnx
    $PY - "$CONFIG" <<'EOF'
import json, sys
tiny = json.load(open("net/configs/tiny.json"))
tiny.update(source="gpu", amp="bf16", steps=1000000, val_size=16, panoramas={"kind": "stadium", "seeds": {"split": "train", "n": 2}, "size": [512, 256]},
            val_panoramas={"kind": "stadium", "seeds": {"split": "val", "n": 1}, "size": [512, 256]}, cache_dir="data_cache")
json.dump(tiny, open(sys.argv[1], "w"))
EOF
  fi
  install_there
  { nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv 2>/dev/null || echo "no nvidia-smi"
    $PY -c 'import torch; print("torch", torch.__version__, "cuda", torch.cuda.is_available())'; } 2>&1
  echo "== [$((SECONDS - t0)) s] stadium panoramas ($NTRAIN train, 4 val, $NTEST test at $SIZE)"
  $PY -m net.data --split train --n $NTRAIN --split val --n 4 --split test --n $NTEST --size $SIZE | tail -2
  if [ -n "$INIT" ] && [ ! -e "$INIT" ]; then
    INIT=runs/shipped_from_onnx.pt
    echo "== [$((SECONDS - t0)) s] no net/checkpoints/continue.pt: the shipped model rebuilt as $INIT"
    [ -e $INIT ] || $PY -m net.from_onnx --onnx glradial/models/glradial_k1k2.onnx --out $INIT | tail -1
  fi
  [ -n "$INIT" ] && EXTRA=(--init "$INIT")
  echo "== [$((SECONDS - t0)) s] throughput check (bench/bench_train_throughput.py, $BENCH_S s a phase)"
  timeout 120 $PY bench/bench_train_throughput.py --config $CONFIG --seconds $BENCH_S --amp bf16 --panoramas 16 --sources gpu 2>&1 | tee "$OUT/throughput.txt"
  echo "== [$((SECONDS - t0)) s] training $TRAIN_S s with the GPU batch source ($CONFIG, init ${INIT:-none})"
  rm -rf $RUN
  timeout $((TRAIN_S + 150)) $PY -m net.train --config $CONFIG --out $RUN --time-budget-s $TRAIN_S "${EXTRA[@]}" < /dev/null
  cp $RUN/train.csv "$OUT/" 2>/dev/null
  echo "== [$((SECONDS - t0)) s] export and evaluation against the shipped model"
  local facts="{\"session\": \"device_session.sh session\", \"train_s\": $TRAIN_S, \"init\": \"${INIT:-none}\", \"gpu\": \"$(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1)\"}"
  $PY -m net.export --checkpoint $RUN/best.pt --out "$OUT/model.onnx" --run-config $RUN/config.json --training "$facts" | tail -2
  $PY - $RUN/best.pt "$OUT/continue.pt" <<'EOF'
import sys, torch
state = torch.load(sys.argv[1], map_location="cpu", weights_only=False)  # best.pt holds the EMA weights
torch.save({"model": state["model"], "model_config": state["model_config"], "step": state["step"], "val": state.get("val")}, sys.argv[2])
print(f"continue.pt: {sys.argv[2]} (step {state['step']}, val {state.get('val')})")
EOF
  ls -la "$OUT/continue.pt"
  $PY -m net.compare $REF "$OUT/model.onnx" --split test --test-panoramas $NTEST --n $NVAL \
    --panorama-size "${SIZE/ /x}" --out /tmp/compare
  echo "== [$((SECONDS - t0)) s] done"
}

case "${1:-}" in
  wheels) wheels ;;
  session)
    session 2>&1 | tee "$OUT/session.log" ;;
  bench)
    install_there
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv | tee "$OUT/gpu.txt"
    $PY -c 'from glradial import egl; print("GL renderer:", egl.renderer_name(egl.thread_context()))' 2>&1 | tee -a "$OUT/gpu.txt"
    for b in "bench_correct.py --frames 60" "bench_crops.py --rounds 5" "bench_stadium.py --full" \
             "bench_estimate.py --frames 30 --pitch glradial/data/usl_broadcast_0195.jpg"; do
      echo "== $PY bench/$b" | tee -a "$OUT/bench.txt"
      timeout 150 $PY bench/$b 2>&1 | tee -a "$OUT/bench.txt"
    done ;;
  train)
    install_there
    RUN=runs/stage12
    mkdir -p $RUN
    if [ ! -e data_cache/.stage12 ]; then  # the panoramas (cached; kept while the machine stays warm)
      $PY -m net.data --split train --n 80 --split val --n 4 --split test --n 8 --size 4096 2048 > "$OUT/data.txt" 2>&1 \
        && touch data_cache/.stage12
      tail -3 "$OUT/data.txt"
    fi
    [ -e runs/shipped_from_onnx.pt ] || $PY -m net.from_onnx --onnx glradial/models/glradial_k1k2.onnx \
      --out runs/shipped_from_onnx.pt 2>&1 | tail -1
    # in the foreground: a machine left idle between calls is given back with the run on it
    $PY -m net.train --config net/configs/stage12_multitask.json --out $RUN --init runs/shipped_from_onnx.pt \
      --resume --stop-after-s "${2:-420}" >> $RUN/log.txt 2>&1 < /dev/null
    tail -5 $RUN/log.txt
    cp $RUN/last.pt $RUN/best.pt $RUN/train.csv $RUN/log.txt "$OUT/" 2>/dev/null ;;
  finish)
    install_there
    RUN=runs/stage12
    tail -4 $RUN/log.txt
    $PY -m net.export --checkpoint $RUN/best.pt --out $RUN/model.onnx 2>&1 | tail -2
    cp $RUN/log.txt $RUN/train.csv $RUN/best.pt $RUN/model.onnx "$OUT/" 2>/dev/null
    for m in glradial/models/glradial_k1k2.onnx $RUN/model.onnx; do
      n=$(basename $(dirname $m)); $PY -m glradial evaluate --model $m --out /tmp/eval_$n -q --threads 16 2>&1 | tail -3
      cp /tmp/eval_$n/metrics.json $OUT/eval_$n.json
    done
    $PY -m net.error_calibration --model $RUN/model.onnx --split val --out $OUT/val_errors.npz
    $PY -m net.error_calibration --model $RUN/model.onnx --split test --panoramas 8 --out $OUT/test_errors.npz ;;
  *)
    echo "usage: bash scripts/device_session.sh wheels|session|bench|train [SECONDS]|finish" >&2; exit 2 ;;
esac
