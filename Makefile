# `make demo` and `make test` do all set-up themselves: a .venv, the Rust core built by maturin
# (release, tuned for this CPU), the package installed editable with its dev extras.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
# The core is built on the machine that runs it, so let the compiler use its vector units.
export RUSTFLAGS ?= -C target-cpu=native
RUST_SOURCES := $(shell find crates -name '*.rs' -o -name Cargo.toml) Cargo.toml

.PHONY: demo test install lint bench clean

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
	PYO3_PYTHON=$(abspath $(BIN)/python) cargo clippy --workspace --all-targets -- -D warnings
	$(BIN)/ruff check python tests benchmarks
	$(BIN)/ruff format --check python tests benchmarks

# Every benchmark prints one JSON object; docs/benchmarks.md is generated from them.
BENCHMARKS := em raycast loaders selection codec registration place merge backend planner fleet security live

bench: install
	for b in $(BENCHMARKS); do $(BIN)/python benchmarks/$$b.py > bench-$$b.json || exit 1; done
	$(BIN)/python benchmarks/report.py

clean:
	rm -rf $(VENV) target
