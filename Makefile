# Two entry points (see README): `make run` and `make test`. Both create the
# virtual environment in .venv on first use and install everything the project needs.
# `make lint` (ruff and mypy, configured in pyproject.toml) runs in CI before the tests.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: run test lint bench map clean ros bags

$(STAMP): pyproject.toml ros2_ws/src/moose_ros/setup.py
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -e '.[test,sweep,dask,lint]' -e 'ros2_ws/src/moose_ros[parquet]'
	touch $(STAMP)

run: $(STAMP)
	$(BIN)/moose simulate --scenario paper_v7_tau1.4 --json runs/extreme/summary.json --plot runs/extreme/figure.png

test: $(STAMP)
	$(BIN)/python -m pytest

lint: $(STAMP)
	$(BIN)/ruff check
	$(BIN)/mypy

bench: $(STAMP)
	$(BIN)/python bench/bench_mpc.py
	$(BIN)/python bench/bench_closed_loop.py
	$(BIN)/python bench/bench_plant.py
	$(BIN)/python bench/bench_graph.py
	$(BIN)/python bench/bench_memory.py
	$(BIN)/python bench/bench_sweep.py

# the shipped criticality map of the paper region (README, docs/design.md): ~2,700 cases, a few minutes on 2 cores
MAP := docs/maps/paper_region
map: $(STAMP)
	rm -rf $(MAP)
	$(BIN)/moose sweep --speed 4:8:1 --tau 1:5:0.5 --nu 0.1:1.0:0.1 --mu paper,0.8 --planner combined,mpc,msf -o $(MAP)
	$(BIN)/moose sweep plot $(MAP)
	rm $(MAP)/cases.jsonl

# Optional: ROS 2 Jazzy (rclpy, Fast DDS) from wheels in .venv-ros and moose_msgs built for it (README).
ros:
	$(PYTHON) ros2_ws/ros_prefix.py

clean:
	rm -rf $(VENV) .venv-ros runs

# The example bags of bags/ (README there): two lockstep runs and one run of the node graph.
bags: $(STAMP)
	rm -rf bags/paper_v7_tau1.4_combined bags/paper_v5_tau3_combined bags/paper_v7_tau1.4_combined_graph
	$(BIN)/moose simulate --scenario paper_v7_tau1.4 --bag bags/paper_v7_tau1.4_combined
	$(BIN)/moose simulate --scenario paper_v5_tau3 --bag bags/paper_v5_tau3_combined
	$(BIN)/moose launch --scenario paper_v7_tau1.4 --bag bags/paper_v7_tau1.4_combined_graph
