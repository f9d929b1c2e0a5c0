# Two entry points (see README): `make run` and `make test`. Both create the
# virtual environment in .venv on first use and install everything the project needs.
# `make lint` (ruff and mypy, configured in pyproject.toml) runs in CI before the tests.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: run test lint mutation planted-bugs bench map clean ros bags

$(STAMP): pyproject.toml ros2_ws/src/moose_ros/setup.py
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -e '.[test,sweep,dask,lint,commonroad]' -e 'ros2_ws/src/moose_ros[parquet]'
	touch $(STAMP)

run: $(STAMP)
	$(BIN)/moose simulate --scenario paper_v7_tau1.4 --json runs/extreme/summary.json --plot runs/extreme/figure.png

lint: $(STAMP)
	$(BIN)/ruff check
	$(BIN)/mypy

# The test suite (README, CI), under coverage.py with every Python subprocess included (nodes, CLI runs, the
# xdist workers): the report of src/moose and moose_ros, and a floor of 90 % on src/moose.  Data in .coverage-data/.
# Two phases: every test not marked `realtime` on TEST_JOBS cores (pytest-xdist, groups of tests that share a
# costly fixture or a file stay in one worker: tests/conftest.py), then the `realtime` ones alone, one at a time
# (judged against the wall clock, they need the cores to themselves).  Each phase writes a JUnit report to
# runs/tests/ (python bench/test_durations.py tabulates where the time went).
# First the sources are compiled to bytecode (compileall: only what changed), and the tests run with Python writing
# bytecode whatever PYTHONDONTWRITEBYTECODE says, so that the suite's hundreds of Python processes (nodes, launchers,
# CLI runs, workers) load it rather than compile the sources again (a moose launch spent a quarter of its CPU time so)
# and each pytest process loads the test modules as pytest rewrote them for its asserts, cached beside them, rather
# than rewriting all of them (collecting the suite under coverage: 16 CPU-s so, 6 from the cache; docs/testing.md).
# A quick run without coverage: .venv/bin/python -m pytest [-n 2].  Extra pytest arguments of both phases:
# make test PYTEST_ARGS='-k can' (a phase that selects no test is skipped; both selecting none is an error).
COVERAGE_FLOOR ?= 90
TEST_JOBS ?= 2
# The tests' temporary files, outside the checkout (a test of a fresh directory must not find the project's files above
# it) and one folder per checkout, so two checkouts' runs at once never share one: a failing test's files (its bag,
# its launch log) stay there until the next `make test` (pyproject.toml: tmp_path_retention_policy).
TEST_TMP ?= $(or $(TMPDIR),/tmp)/moose-tests-$(shell printf %s '$(CURDIR)' | cksum | cut -d' ' -f1)
# coverage.py's core: on Python 3.12 and newer its sys.monitoring core (`sysmon`), which stops reporting a line once
# it has been seen, where the C tracer is called on every line run (the in-process tests of test_reproduce, test_msf
# and test_mpc: 26 CPU-s without coverage, 72 under the C tracer, 40 under sysmon, on 3.12; the whole suite 488 s:
# docs/testing.md, "Python 3.12"); on 3.11 the C tracer (coverage warns about a sysmon it cannot have, so it is not
# asked for).  The project's venv decides, read when the recipe runs (after the venv exists); COVERAGE_CORE=ctrace
# make test overrides it.
COVERAGE_CORE ?= $(shell $(BIN)/python -c 'import sys; print("sysmon" if sys.version_info >= (3, 12) else "ctrace")')
COVERAGE = env -u PYTHONDONTWRITEBYTECODE COVERAGE_CORE=$(COVERAGE_CORE) MOOSE_COVERAGE_DIR=$(CURDIR)/.coverage-data \
	$(BIN)/python -m coverage
test: $(STAMP)
	rm -rf .coverage-data runs/tests && mkdir -p .coverage-data runs/tests "$(TEST_TMP)"
	$(BIN)/python -m compileall -q src ros2_ws/src tests bench > /dev/null
	@a=0; b=0; \
	$(COVERAGE) run -m pytest -n $(TEST_JOBS) --dist loadgroup -m 'not realtime' --basetemp="$(TEST_TMP)/parallel" \
		--junitxml=runs/tests/parallel.xml $(PYTEST_ARGS) || a=$$?; \
	$(COVERAGE) run -m pytest -m realtime --basetemp="$(TEST_TMP)/realtime" --junitxml=runs/tests/realtime.xml \
		$(PYTEST_ARGS) || b=$$?; \
	if [ $$a -eq 5 ] && [ $$b -eq 5 ]; then echo "make test: no test selected"; exit 5; fi; \
	if [ $$a -eq 5 ]; then a=0; fi; if [ $$b -eq 5 ]; then b=0; fi; \
	exit $$(( a ? a : b ))
	$(COVERAGE) combine -q
	$(COVERAGE) report --sort=cover
	$(COVERAGE) report --include='src/moose/*' --format=total --fail-under=$(COVERAGE_FLOOR) > /dev/null \
		|| { echo "coverage of src/moose below $(COVERAGE_FLOOR) %"; exit 1; }
	@echo "line coverage of src/moose: $$($(COVERAGE) report --include='src/moose/*' --format=total) % (floor $(COVERAGE_FLOOR) %)"

# Mutation score of the safety- and verdict-critical modules (bench/mutation.py; about 12 min on 2 cores; not in CI).
# One module: make mutation MODULES=canbus.codec.  The table in docs/testing.md: bench/mutation.py --table --docs
mutation: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[mutation]'
	$(BIN)/python bench/mutation.py $(MODULES)

# The planted bugs of issues 14 and 25, each caught by the default test run? (bench/planted_bugs.py; not in CI)
planted-bugs: $(STAMP)
	$(BIN)/python bench/planted_bugs.py

bench: $(STAMP)
	$(BIN)/python bench/bench_mpc.py
	$(BIN)/python bench/bench_closed_loop.py
	$(BIN)/python bench/bench_plant.py
	$(BIN)/python bench/bench_graph.py
	$(BIN)/python bench/bench_cdr.py
	$(BIN)/python bench/bench_graph_start.py
	$(BIN)/python bench/bench_memory.py
	$(BIN)/python bench/bench_sweep.py
	$(BIN)/python bench/bench_sweep_per_core.py

# the shipped criticality map of the paper region (docs/maps.md): ~2,700 cases, a few minutes on 2 cores
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
