# Single entry point. `make demo` sets everything up and renders the paper's
# scenes; `make test` runs every test of the project (what .ci/run calls).

SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
CARGO ?= cargo
export CARGO_TERM_COLOR ?= never

.PHONY: demo setup core test test-rust lint bench

demo: setup core

# System packages, the Python venv with pinned packages (idempotent).
setup:
	bash scripts/setup.sh

core:
	$(CARGO) build --release -p stam-core

lint:
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings

test-rust:
	$(CARGO) test --workspace

test: setup lint test-rust

bench:
	$(CARGO) bench -p stam-core --bench brdf
