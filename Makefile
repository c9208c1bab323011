# One-command set-up: every target creates .venv, installs the pinned requirements and
# colcon-builds the package when needed, so a clean clone needs only python3 and the registries.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
STAMP := $(VENV)/.requirements-installed
INSTALL := install/imu_allan
# The environment `source install/setup.bash` would give, without needing a ROS install.
RUN_ENV := PATH="$(CURDIR)/$(VENV)/bin:$$PATH" \
	AMENT_PREFIX_PATH="$(CURDIR)/$(INSTALL):$(CURDIR)/$(VENV)" \
	PYTHONPATH="$(CURDIR)/$(INSTALL)/lib/python3.11/site-packages$${PYTHONPATH:+:$$PYTHONPATH}" \
	MPLBACKEND=Agg
TESTS ?= test
PYTEST_ARGS ?=
# Test processes (pytest-xdist; auto: one per core).  Each test file runs whole on one worker
# (--dist loadfile): its module fixtures are made once, and tests that share a fixed path
# (test_package_deps.py's build/rosdep-*) or a module's DDS domain never run side by side.
# Every worker has its own ROS_DOMAIN_IDs (test/conftest.py).  TEST_JOBS=0: one process.
TEST_JOBS ?= auto
XDIST = $(if $(filter 0,$(TEST_JOBS)),,-n $(TEST_JOBS) --dist loadfile)
# `make quick`: the core, formats and report tests that need no build and no ROS, imported
# from the source tree (no colcon build; numba caches its kernels beside the sources).
QUICK_TESTS ?= test/core test/formats test/report test/test_import_direction.py
QUICK_MARKS := not slow and not ros and not browser

.PHONY: all venv build launch-stack browser test quick lint demo bench clean

all: build

$(STAMP): requirements.txt
	test -x $(VPY) || $(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install --quiet --disable-pip-version-check -r requirements.txt
	touch $(STAMP)

venv: $(STAMP)

# colcon's isolated layout: install/imu_allan/lib/imu_allan/<executable>.
# Then byte-compile the installed modules, as pip and setuptools do on install, but here
# explicitly: setuptools skips it under PYTHONDONTWRITEBYTECODE (set on some CI machines), and
# every command would then compile the package's sources again (60 ms of `analyze`).
build: $(STAMP)
	$(RUN_ENV) $(VENV)/bin/colcon --log-base log build --paths . \
		--build-base build --install-base install --event-handlers console_cohesion- summary-
	$(VPY) -m compileall -q $(INSTALL)/lib/python3.11/site-packages/imu_allan > /dev/null

lint: $(STAMP)
	$(VENV)/bin/ruff check imu_allan test scripts bench launch setup.py

# launch and launch_ros are not on PyPI: an importable one (a ROS install) is used, else the
# vendored Jazzy sources in the shared folder are built into the venv, once per venv (about a
# minute; build_launch.sh stamps it). Without either, the launch tests skip and say why.
# (the shared folder beside the checkout; the tests read IMU_ALLAN_SHARED too)
IMU_ALLAN_SHARED ?= ../shared
LAUNCH_VENDOR := $(IMU_ALLAN_SHARED)/vendor/ros2_jazzy
launch-stack: $(STAMP)
	@$(RUN_ENV) $(VPY) -c 'import launch_ros' 2>/dev/null \
		|| { test -f $(LAUNCH_VENDOR)/build_launch.sh \
			&& bash $(LAUNCH_VENDOR)/build_launch.sh $(VPY) $(VENV); } \
		|| echo 'launch_ros neither importable nor buildable: the launch tests skip'

# The HTML page tests run in Debian's chromium: installed with apt when missing and apt is
# usable (root); never a failure here: without a browser those tests skip and say why.
browser:
	@command -v chromium > /dev/null 2>&1 || { \
		if [ "$$(id -u)" = 0 ] && command -v apt-get > /dev/null 2>&1; then \
			(apt-get update -qq && apt-get install -y -qq chromium > /dev/null) \
				|| echo 'apt could not install chromium: the browser tests skip'; \
		else echo 'no chromium (and no apt as root to install it): the browser tests skip'; fi; }

test: build launch-stack browser
	$(RUN_ENV) $(VPY) -m pytest -q $(XDIST) $(TESTS) $(PYTEST_ARGS)

quick: $(STAMP)
	PYTHONPATH="$(CURDIR)$${PYTHONPATH:+:$$PYTHONPATH}" MPLBACKEND=Agg \
		$(VPY) -m pytest -q $(XDIST) -m '$(QUICK_MARKS)' $(QUICK_TESTS) $(PYTEST_ARGS)

demo: build
	$(RUN_ENV) $(VPY) scripts/demo.py

bench: build
	$(RUN_ENV) $(VPY) scripts/bench.py

clean:
	rm -rf build install log $(VENV)
