# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0
#
# Every target sets itself up from nothing: a venv with the ROS 2 Jazzy wheels, the CMake path fix,
# a colcon build of both packages. Stamps make a re-run with nothing changed cost almost nothing.
SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
.DEFAULT_GOAL := help

PYTHON ?= python3
VENV := .venv
ROOT := $(abspath .)
DEPS_STAMP := $(VENV)/.deps.stamp
BUILD_STAMP := install/.build.stamp
REQUIREMENTS := $(wildcard requirements/*.txt)
SOURCES := $(shell find wctls_msgs wctls_ros -type f -not -path '*/__pycache__/*' \
             -not -name '*.pyc' 2>/dev/null)
# Every recipe line that runs project code does so inside the venv + install overlay.
WITH_ENV := source tools/env.sh &&
PYTEST_ARGS ?=
# The tests that need numpy and numba alone run a second time with the oldest numpy
# requirements/python.txt admits: Ubuntu 24.04's 1.26, which an apt install of ROS 2 Jazzy uses.
OLDEST_NUMPY_VENV := .venv-oldest-numpy
OLDEST_NUMPY_STAMP := $(OLDEST_NUMPY_VENV)/.deps.stamp
NUMPY_ONLY_TESTS := $(addprefix wctls_ros/test/,test_core_lines.py test_core_pipeline.py \
                      test_core_precompile.py test_core_segmentation.py test_rplidar_scan.py \
                      test_simulation.py)

.PHONY: help deps build demo test lint bench results docs clean

help:
	@echo 'make demo   set up, then run the S1 emulator, driver and feature node live for ~20 s'
	@echo 'make test   set up (venv, ROS 2 wheels, colcon build) and run every test and the lint'
	@echo 'make build  set up and colcon build both packages into install/'
	@echo 'make lint   only the ament-style lint (flake8 with ament rules, pep257)'
	@echo 'make bench  run the benchmarks and print their figures'
	@echo 'make results  regenerate docs/results (evaluation of simulated and real static scans)'
	@echo 'make docs   regenerate the parameter tables of docs/user_guide.md from the schema'
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

$(OLDEST_NUMPY_STAMP): requirements/python.txt requirements/test.txt tools/pip_install.sh
	PYTHON=$(PYTHON) tools/pip_install.sh $(OLDEST_NUMPY_VENV) \
	  "numpy==$$(sed -n 's/^numpy>=//p' requirements/python.txt).*" \
	  $$(grep -hE '^(numba|PyYAML|pytest|hypothesis)[=>]' requirements/*.txt)
	touch $@

build: $(BUILD_STAMP)

$(BUILD_STAMP): $(DEPS_STAMP) $(SOURCES)
	$(WITH_ENV) colcon build --event-handlers console_cohesion- summary+ \
	  --cmake-args -DPython3_EXECUTABLE=$(ROOT)/$(VENV)/bin/python
	@# Compile the feature pipeline into numba's cache now, not at the first scan.
	$(WITH_ENV) python -c 'from wctls_ros.core import warm_up; \
	  print(f"wctls_ros: feature pipeline compiled in {warm_up():.1f} s")'
	touch $@

demo: $(BUILD_STAMP)
	$(WITH_ENV) install/wctls_ros/lib/wctls_ros/demo

test: $(BUILD_STAMP) $(OLDEST_NUMPY_STAMP)
	$(WITH_ENV) python -m pytest $(PYTEST_ARGS)
	@# Its own JIT cache: code compiled against one numpy is not reused under another.
	NUMBA_CACHE_DIR=$(ROOT)/$(OLDEST_NUMPY_VENV)/numba-cache \
	  PYTHONPATH=wctls_ros:wctls_ros/test $(OLDEST_NUMPY_VENV)/bin/python -m pytest -p no:cacheprovider \
	  -o addopts='-ra --strict-markers' --junitxml=out/test-results-oldest-numpy.xml \
	  $(NUMPY_ONLY_TESTS)

lint: $(BUILD_STAMP)
	$(WITH_ENV) python -m pytest -m linter $(PYTEST_ARGS)

bench: $(BUILD_STAMP)
	$(WITH_ENV) for b in wctls_ros/benchmark/bench_*.py; do python "$$b"; done

results: $(BUILD_STAMP)
	$(WITH_ENV) tools/make_results.sh

docs: $(BUILD_STAMP)
	$(WITH_ENV) python -m wctls_ros.params --write docs/user_guide.md

clean:
	rm -rf build install log out
