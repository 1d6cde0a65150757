# glradial: two commands do all set-up on a fresh Debian/Ubuntu machine: `make demo` and `make test`.
# Everything goes into the project's own virtual environment (.venv), so a system Python that is
# externally managed (PEP 668) is never touched. `make demo` installs the runtime dependencies only;
# `make test` adds the test tools, Ray (the `cluster` extra: the job tests start a real local Ray) and torch 2.13.0 (the registry's default build; CUDA with triton on
# Linux x86_64, which runs on the CPU; glradial keeps triton's LLVM apart from Mesa's: gl/llvm_guard.py).
SYSPY ?= python3
VENV := .venv
PY := $(VENV)/bin/python
RUNTIME_STAMP := $(VENV)/.runtime.stamp
DEV_STAMP := $(VENV)/.dev.stamp

.PHONY: setup system-deps demo test bench train evaluate clean

system-deps:
	@bash scripts/install_system_deps.sh

$(PY): scripts/install_system_deps.sh
	@bash scripts/install_system_deps.sh
	$(SYSPY) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(RUNTIME_STAMP): pyproject.toml $(PY)
	$(PY) -m pip install --quiet -e .
	@touch $@

$(DEV_STAMP): pyproject.toml $(PY)
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e ".[train,test,bench,cluster]"
	@touch $@ $(RUNTIME_STAMP)

setup: $(DEV_STAMP)

demo: $(RUNTIME_STAMP)
	$(PY) -m glradial demo --out out/demo

test: $(DEV_STAMP)
	$(PY) -m pytest -q tests
	$(PY) -m pytest -q --doctest-modules glradial

bench: $(DEV_STAMP)
	$(PY) bench/bench_correct.py
	$(PY) bench/bench_crops.py
	$(PY) bench/bench_stadium.py
	$(PY) bench/bench_estimate.py
	$(PY) bench/bench_video.py

train: $(DEV_STAMP)
	$(PY) -m net.data --split train --n 80 --split val --n 4 --split test --n 8 --size 4096 2048
	$(PY) -m net.train --config net/configs/stage01_128.json --out runs/stage01
	$(PY) -m net.train --config net/configs/stage02_192.json --out runs/ft192 --init runs/stage01/best.pt
	$(PY) -m net.train --config net/configs/stage03_256.json --out runs/ft256 --init runs/ft192/best.pt
	$(PY) -m net.train --config net/configs/stage04_384.json --out runs/ft384 --init runs/ft256/best.pt
	$(PY) -m net.train --config net/configs/stage05_grow_384.json --out runs/grow384 --init runs/ft384/best.pt
	$(PY) -m net.train --config net/configs/stage06_joint_384.json --out runs/joint384 --init runs/grow384/last.pt
	$(PY) -m net.train --config net/configs/stage07_grow2_384.json --out runs/grow2_384 --init runs/joint384/best.pt
	$(PY) -m net.train --config net/configs/stage08_extend_384.json --out runs/extend384 --init runs/grow2_384/best.pt
	# stages 9-10 ran on a GPU under a step-time budget; --steps with no budget gives the same schedule anywhere
	$(PY) -m net.train --config net/configs/stage09_gpu_384.json --out runs/gpu384 --init runs/extend384/best.pt --steps 11809 --time-budget-s 0
	$(PY) -m net.train --config net/configs/stage10_shipped.json --out runs/gpu384b --init runs/gpu384/last.pt --steps 3485 --time-budget-s 0

evaluate: $(DEV_STAMP)
	$(PY) -m glradial evaluate --model glradial/models/glradial_k1k2.onnx --out docs/eval --field-panorama tests/data/panorama_field_2048x1024.jpg

clean:
	rm -rf $(VENV) out build dist *.egg-info .pytest_cache
