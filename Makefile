# wand_calib_ros: the two entry points of the README.
#   make demo  - create .venv, install, replay a rendered mixed rig through the live ROS 2 nodes, /calibrate
#   make demo-offline - the core without ROS on the paper's simulated two-fisheye rig
#   make test  - create .venv, install with test tools, run ruff, mypy and the test suite
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
DEMO_DIR := demo_output

.PHONY: demo demo-offline test test-old-cpu setup lint clean

$(BIN)/activate:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

$(VENV)/.installed: $(BIN)/activate requirements.txt requirements-dev.txt setup.py
	$(BIN)/pip install --quiet -r requirements-dev.txt
	$(BIN)/pip install --quiet --no-deps aniposelib==0.8.0
	$(BIN)/pip install --quiet --no-deps -e .
	touch $@

setup: $(VENV)/.installed

demo: setup
	$(BIN)/python -m wand_calib_ros.nodes.demo --out $(DEMO_DIR)/live

demo-offline: setup
	$(BIN)/wand-calib simulate paper --seed 1 --noise 1.0 --out $(DEMO_DIR)
	$(BIN)/wand-calib calibrate --cameras $(DEMO_DIR)/cameras.yaml \
		--observations $(DEMO_DIR)/observations.csv --output $(DEMO_DIR)/result.yaml \
		--camera-info-dir $(DEMO_DIR)/camera_info --truth $(DEMO_DIR)/truth.yaml
	$(BIN)/wand-calib -q report --result $(DEMO_DIR)/result.yaml --cameras $(DEMO_DIR)/cameras.yaml \
		--observations $(DEMO_DIR)/observations.csv --out $(DEMO_DIR)/report

lint: setup
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

test: setup lint
	$(BIN)/python -m pytest -q

# The suite as an older x86-64 CPU computes it: numpy's SSE kernels only (no AVX2/AVX-512), OpenBLAS's Nehalem
# core, OpenCV without AVX. A tolerance that holds only on this machine's rounding fails here.
test-old-cpu: setup
	NPY_DISABLE_CPU_FEATURES="AVX512_SPR AVX512_ICL X86_V4 X86_V3" OPENBLAS_CORETYPE=Nehalem \
	OPENCV_CPU_DISABLE="AVX512_SKX,AVX512_ICL,AVX2,FMA3,AVX,F16C" $(BIN)/python -m pytest -q

clean:
	rm -rf $(VENV) $(DEMO_DIR) build install log *.egg-info
