# Single entry point. `make demo` sets everything up and renders the paper's
# scenes; `make test` runs every test of the project (what .ci/run calls).
# Targets:
#   make core     Rust core (cargo, release): target/release/libstam.{a,so}
#   make plugin   Mitsuba BSDF plugin: build/plugins/diffraction.so
#   make setup    system packages + .venv (scripts/setup.sh)
#   make render-tool  the Rust-only reference renderer: target/release/stam-render
#   make demo     setup, core, plugin, then render the paper's subjects (scenes/hero_*.xml)
#                 to out/gallery/ (PNG, EXR, contact_sheet.png; scripts/render_gallery.py,
#                 docs/gallery.md)
#   make animation  the talk's animations on a local Dask cluster of ANIM_WORKERS
#                 processes: out/animation/{cd,brushed}/ (frames, MP4, GIF;
#                 scripts/render_animation.py, docs/animation.md)
#   make compare  Mitsuba vs Rust-only comparison to out/compare/ (scripts/compare.py;
#                 exits non-zero when a check fails)
#   make heightmaps  the synthetic height maps of scenes/heightmap.xml:
#                 scenes/heightmaps/*.npy (scripts/make_heightmaps.py, seconds)
#   make guide    the pictures of docs/guide.md: docs/img/guide/*.png
#                 (scripts/render_guide.py, about a minute on two cores)
#   make explore  the live material explorer in the browser: serves it on
#                 127.0.0.1:8765 and opens it (python -m stam_diffraction.explore,
#                 docs/explorer.md; EXPLORE_ARGS, e.g. --no-browser)
#   make wheel    the pip-installable package stam-diffraction: dist/*.whl
#                 (pyproject.toml; its CMakeLists.txt runs `make plugin`)
#   make fuzz     the JSON/ABI fuzzing at depth (30,000 cases per strategy)
#   make check    the contributors' inner loop (lint, the fast Rust and Python
#                 tests; at most 3 minutes warm); `make test` runs everything
# Variables: PYTHON (the venv's python), STAM_LIB (static core library to link;
# override to link a different build of the core).

PYTHON    ?= .venv/bin/python
CARGO     ?= cargo
CXX       ?= g++
BUILD     ?= build

STAM_LIB_DEFAULT := target/release/libstam.a
STAM_LIB  ?= $(STAM_LIB_DEFAULT)
STAM_H    := rust-core/include/stam.h
PLUGIN_SO := $(BUILD)/plugins/diffraction.so
PLUGIN_OBJ := $(BUILD)/plugins/diffraction.o
PLUGIN_SRC := mitsuba-plugin/diffraction.cpp
PLUGIN_HDR := mitsuba-plugin/batch.h mitsuba-plugin/code_version.h mitsuba-plugin/params_json.h mitsuba-plugin/program.h \
              mitsuba-plugin/jit_path.h mitsuba-plugin/plugin_params.h mitsuba-plugin/shape_kind.h \
              mitsuba-plugin/param_textures.h
# The mitsuba and drjit versions the plugin is compiled against (JSON); the
# package stam_diffraction refuses to load the plugin under others.
PLUGIN_ABI := $(BUILD)/plugins/diffraction.abi.json

# Package locations, computed once and only when needed (no import of mitsuba).
pkgdir = $(shell $(PYTHON) -c "import importlib.util as u; print(u.find_spec('$(1)').submodule_search_locations[0])")
MI_DIR = $(eval MI_DIR := $(call pkgdir,mitsuba))$(MI_DIR)
DR_DIR = $(eval DR_DIR := $(call pkgdir,drjit))$(DR_DIR)
NB_INC = $(eval NB_INC := $(shell $(PYTHON) -c "import nanobind; print(nanobind.include_dir())"))$(NB_INC)
# Mitsuba's shape.h includes tsl/robin_map.h, which the wheel lacks and nanobind ships.

# -march=haswell is REQUIRED: it matches the wheel's vector layout (docs/mitsuba.md).
PLUGIN_CXXFLAGS = -std=c++17 -O3 -march=haswell -fPIC -fvisibility=hidden \
	-DMI_ENABLE_LLVM=1 -DMI_ENABLE_CUDA=1 -DMI_ENABLE_EMBREE=1 -DMI_ENABLE_AUTODIFF=1 \
	-Wall -Wextra -Wshadow \
	-isystem $(MI_DIR)/include -isystem $(DR_DIR)/include -isystem $(NB_INC) \
	-isystem $(dir $(NB_INC))ext/robin_map/include
# The run path is that of the installed package (site-packages/stam_diffraction/plugins/),
# for the wheel ships this file; wherever the plugin lies, Mitsuba has loaded these
# libraries before it, and the loader finds them by name, as for Mitsuba's own plugins.
PLUGIN_LDFLAGS = -shared -Wl,--no-undefined -Wl,--exclude-libs,ALL -L$(MI_DIR) -L$(DR_DIR) \
	-Wl,-rpath,'$$ORIGIN/../../mitsuba' -Wl,-rpath,'$$ORIGIN/../../drjit'
PLUGIN_LIBS = $(STAM_LIB) -lmitsuba -ldrjit-core -ldrjit-extra -lnanothread -lpthread -ldl -lm

export CARGO_TERM_COLOR ?= never
SHELL := /bin/bash

.PHONY: explore all demo animation compare guide heightmaps render-tool core plugin wheel setup clean-plugin test test-rust test-python lint check bench bench-render stress fuzz furnace FORCE
all: plugin

demo: setup plugin heightmaps
	@start=$$(date +%s); \
	$(PYTHON) scripts/render_gallery.py && \
	echo "[demo] done: out/gallery/contact_sheet.png (renders $$(( $$(date +%s) - start )) s)"

EXPLORE_ARGS ?=
explore: setup core heightmaps
	PYTHONPATH=python $(PYTHON) -m stam_diffraction.explore $(EXPLORE_ARGS)

# The compact disc turning under the strip lights, a lamp swinging over brushed metal.
ANIM_WORKERS ?= 2
ANIM_ARGS    ?= --frames 48 --res 320 --spp 64
animation: setup plugin
	$(PYTHON) scripts/render_animation.py --scene cd $(ANIM_ARGS) --workers $(ANIM_WORKERS)
	$(PYTHON) scripts/render_animation.py --scene brushed $(ANIM_ARGS) --workers $(ANIM_WORKERS)

compare: setup plugin render-tool
	$(PYTHON) scripts/compare.py

guide: plugin
	$(PYTHON) scripts/render_guide.py

# The height maps of the `heightmap` surface (scenes/heightmap.xml): the
# script writes all four, gaussian.npy last, so that file stands for them.
heightmaps: scenes/heightmaps/gaussian.npy

scenes/heightmaps/gaussian.npy: scripts/make_heightmaps.py
	$(PYTHON) scripts/make_heightmaps.py --out scenes/heightmaps

render-tool:
	$(CARGO) build --release -p stam-render

setup:
	bash scripts/setup.sh

core:
	$(CARGO) build --release -p stam-core

# The default core library is (re)built by cargo, which knows its sources.
# The plugin's object needs only stam.h: it compiles (a minute on one core)
# while cargo builds the core.
ifeq ($(STAM_LIB),$(STAM_LIB_DEFAULT))
plugin:
	@$(MAKE) --no-print-directory -j2 core $(PLUGIN_OBJ)
	@$(MAKE) --no-print-directory $(PLUGIN_SO)
else
plugin: $(PLUGIN_SO)
endif

# Compiled and linked apart: a change of the core alone relinks (seconds)
# instead of compiling the plugin again (a minute).
$(PLUGIN_OBJ): $(PLUGIN_SRC) $(PLUGIN_HDR) $(STAM_H) $(PLUGIN_ABI)
	@mkdir -p $(dir $@)
	$(CXX) $(PLUGIN_CXXFLAGS) -c $(PLUGIN_SRC) -o $@

$(PLUGIN_SO): $(PLUGIN_OBJ) $(STAM_LIB)
	$(CXX) $(PLUGIN_OBJ) -o $@ $(PLUGIN_LDFLAGS) $(PLUGIN_LIBS)

# Rewritten only when $(PYTHON)'s versions differ from the recorded ones, which
# rebuilds the plugin against their headers.
$(PLUGIN_ABI): FORCE
	@mkdir -p $(dir $@)
	@$(PYTHON) -c 'import json; from importlib.metadata import version; \
		print(json.dumps({p: version(p) for p in ("mitsuba", "drjit")}))' > $@.new
	@if cmp -s $@.new $@; then rm $@.new; else mv $@.new $@; fi

clean-plugin:
	rm -f $(PLUGIN_SO) $(PLUGIN_OBJ) $(PLUGIN_ABI)

# Built with the venv's packages (no build isolation: the pinned mitsuba, drjit,
# nanobind, scikit-build-core and cmake of scripts/requirements.txt); `pip install .`
# builds the same in an isolated environment from pyproject.toml's pins.
wheel:
	rm -f dist/stam_diffraction-*.whl
	$(PYTHON) -m pip wheel --no-build-isolation --no-deps --wheel-dir dist .

lint:
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings

test-rust:
	$(CARGO) test --workspace

# Two (or more) pytest workers (pytest-xdist): a clean checkout compiles its
# Dr.Jit kernels (.drjit-cache) on the first run, one core per process. Each
# file runs in one worker (--dist loadfile): test_wheel.py builds dist/ and
# test_animation.py starts a Dask cluster in module fixtures. The files go
# out longest first (tests/conftest.py; --no-loadscope-reorder keeps that
# order instead of xdist's by test count). The 20 slowest tests are listed at
# the end (a slow CI machine's log shows where its time went).
test-python: plugin render-tool heightmaps
	$(PYTHON) -m pytest -q -n auto --dist loadfile --no-loadscope-reorder --durations=20 tests

# Everything, in the order that fails fastest.
test: setup lint test-rust test-python

# The contributors' inner loop (at most 3 minutes warm on 2 cores): lint, the
# core's unit tests but the slowest (RUST_SLOW_TESTS, each over 2.5 s;
# `cargo test` skips every test whose name contains one), the ABI's contract
# with stam.h, and the Python tests of one variant without the slow ones
# (`pytest --quick`, tests/conftest.py). `make test` runs everything.
RUST_SLOW_TESTS := sampling_programs_pass_chi_square covered_disc_reflects_its_cover \
	a_nearby_material_exports_the_same_code parameters_follow_the_changed_material \
	sampling_variance_against each_order_reflects_the_solvers_efficiency \
	a_differentiated_period_plans_for_its_interval chi2_sampling_programs \
	energy_derivatives_follow_rebuilt_tables order_zero_grid_and_table_against_the_solver \
	texture_sampling_passes_chi_square at_built_rgb_eval_equals_the_plain_one \
	gaussian_rgb_table_is_lazy chi_square_detects_a_wrong_pdf \
	sigma_texture_programs_serve_every_sigma conserving_is_reciprocal pdf_positive_where_brdf_is \
	program_sizes conserving_rgb_matches_native efficiencies_are_reciprocal \
	gaussian_maps_give_the_gaussian_brdf fractal_maps_give_the_fractal_brdf \
	heightmap::tests::chi2_native_sampling heightmap::tests::white_furnace_at_most_one
check: lint plugin render-tool heightmaps
	$(CARGO) test -p stam-core --lib --test stress_regressions -- $(addprefix --skip ,$(RUST_SLOW_TESTS))
	$(CARGO) test -p stam-abi-check
	$(PYTHON) -m pytest -q -n auto --dist loadfile --no-loadscope-reorder --quick tests

# ns per evaluation (docs/performance.md) and run time against error of every
# accuracy knob (docs/accuracy_speed.md, docs/pareto_*.png).
bench-render: plugin heightmaps
	$(PYTHON) scripts/bench_render.py --repeats 7 --processes 3 --write docs/plugin_speed.md
	$(PYTHON) scripts/bench_render.py --repeats 5 --processes 3 \
		--variants scalar_spectral_polarized,llvm_ad_spectral_polarized
	$(PYTHON) scripts/bench_scenes.py --processes 3 --repeats 3

bench:
	$(CARGO) bench -p stam-core --bench brdf
	$(PYTHON) scripts/bench_table.py docs/performance.md
	$(CARGO) run --release -p stress --bin pareto -- target/pareto/errors.json
	$(CARGO) bench -p stress --bench pareto
	$(PYTHON) scripts/plot_pareto.py

# White furnace: directional albedo of every test material, Stam's formula and
# "energy": "conserving", printed as tables (docs/energy.md) and plotted
# (docs/img/energy_furnace.png).
furnace: setup
	@mkdir -p target/furnace docs/img
	$(CARGO) run --release -p stam-core --example furnace -- 100000 target/furnace/albedo.json | tee target/furnace/table.md
	$(PYTHON) scripts/plot_furnace.py target/furnace/albedo.json docs/img/energy_furnace.png

# The full numerical stress run (10^7 evaluations; CI runs 10^5 in test-rust).
stress:
	$(CARGO) run --release -p stress --bin stress -- --count 10000000 --write docs/stress.md

# The JSON/ABI fuzzing at depth: 30,000 cases per strategy (`make test` runs
# 3,000, and 1,000 mutated valid materials; tools/stress/tests/fuzz_json.rs).
fuzz:
	FUZZ_CASES=30000 $(CARGO) test --release -p stress --test fuzz_json -- --nocapture
