# `make demo` and `make test` do all set-up themselves: a .venv, the Rust core built by maturin
# (release, tuned for this CPU), the package installed editable with its dev extras.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
# The core is built on the machine that runs it, so let the compiler use its vector units.
export RUSTFLAGS ?= -C target-cpu=native
RUST_SOURCES := $(shell find crates -name '*.rs' -o -name Cargo.toml) Cargo.toml

.PHONY: demo test install lint bench clean ros1 ros2 station

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: $(BIN)/python pyproject.toml $(RUST_SOURCES)
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $@

install: $(VENV)/.installed

demo: install
	$(BIN)/gmmap demo

test: install
	cargo test -p gmmap-core
	$(BIN)/python -m pytest

# The layer rules (tests/test_layers.py) run with the tests.
lint: install
	cargo fmt --check
	cd tools/ros2dds-bridge && cargo fmt --check
	PYO3_PYTHON=$(abspath $(BIN)/python) cargo clippy --workspace --all-targets -- -D warnings
	$(BIN)/ruff check python tests benchmarks
	$(BIN)/ruff format --check python tests benchmarks

# Every benchmark prints one JSON object; docs/benchmarks.md is generated from them.
BENCHMARKS := em raycast loaders selection codec registration place merge backend planner explore fleet channel security live ros1 ros2 station

bench: install
	for b in $(BENCHMARKS); do $(BIN)/python benchmarks/$$b.py > bench-$$b.json || exit 1; done
	$(BIN)/python benchmarks/report.py

clean:
	rm -rf $(VENV) target

# ROS 1 from Debian (for gmmap robot --ros1 and tests/test_ros1.py): the system Python 3.11's
# rospy and message packages, which the node finds beside the venv's own.
ROS1_PACKAGES := ros-core python3-rospy python3-rosbag python3-sensor-msgs python3-tf2-ros \
	python3-nav-msgs python3-visualization-msgs python3-tf2-msgs
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
ros1:
	$(SUDO) apt-get install -y --no-install-recommends $(ROS1_PACKAGES) || \
	  ($(SUDO) apt-get update && $(SUDO) apt-get install -y --no-install-recommends $(ROS1_PACKAGES))

# Debian's Chromium, for tests/test_station.py: a headless browser opens the station's view.
station:
	$(SUDO) apt-get install -y --no-install-recommends chromium || \
	  ($(SUDO) apt-get update && $(SUDO) apt-get install -y --no-install-recommends chromium)

# ROS 2 against real DDS (tests/test_ros2dds.py): zenoh-plugin-ros2dds in a small host
# (tools/ros2dds-bridge, its own workspace), built into a cache outside the clone keyed by the
# plugin's version, so a second clone on this machine reuses it; CMake and libclang (for
# CycloneDDS, which the plugin builds) from Debian; the cyclonedds package (the stand-in ROS 2
# graph, gmmap.eval.ros2dds) into the venv.
ROS2DDS_VERSION := $(shell sed -n 's/^version = "\(.*\)"/\1/p' tools/ros2dds-bridge/Cargo.toml)
ROS2DDS_TARGET := $(HOME)/.cache/gmmap/ros2dds-bridge-$(ROS2DDS_VERSION)
ros2: install
	command -v cmake >/dev/null && [ -e /usr/lib/llvm-*/lib/libclang.so ] 2>/dev/null || \
	  $(SUDO) apt-get install -y --no-install-recommends cmake libclang-dev || \
	  ($(SUDO) apt-get update && $(SUDO) apt-get install -y --no-install-recommends cmake libclang-dev)
	cd tools/ros2dds-bridge && RUSTFLAGS= CARGO_TARGET_DIR=$(ROS2DDS_TARGET) cargo build --release --locked
	$(BIN)/python -m pip install --quiet "cyclonedds>=0.10"
