# Rokeby — two commands on a fresh machine: `make demo` and `make test`.
# Both bootstrap idempotently: .venv with the pinned packages, then rokeby_native built in release
# mode and installed into .venv. A second run skips what is up to date.

SHELL   := /bin/bash
PYTHON  ?= python3
VENV    := .venv
PY      := $(VENV)/bin/python
PIP     := $(PY) -m pip
SHARED  ?= $(abspath ../shared)
export ROKEBY_SHARED := $(SHARED)

RUST_SRC := Cargo.toml pyproject.toml $(wildcard rust/*/Cargo.toml) $(shell find rust -name '*.rs' 2>/dev/null) $(wildcard python/rokeby_native/*)

.PHONY: ci-phase2 test-gui gui-root all demo dist test test-blender test-matrix bench cargo-test pytest native venv clean help fuzz fuzz-py lint

all: native

help:
	@echo "make demo   build everything and run the demonstration"
	@echo "make test   cargo tests + pytest (bpy in background mode)"
	@echo "make test-blender BPY=4.2.23  the whole pytest suite on another bpy, in .venv-bpy-<version>"
	@echo "make test-matrix  test-blender for each of MATRIX (5.3.0 4.2.23 5.0.1), as CI runs it (CPython 3.11 legs: -m blender; MATRIX_JOBS=2 at once)"
	@echo "make bench  benchmarks, printed next to the reference numbers"
	@echo "make dist   the installable Blender extension zip, dist/rokeby-<version>.zip"
	@echo "make lint   ruff (errors), cargo fmt --check, cargo clippy -D warnings, and the add-on checked against the newest Blender API stubs"
	@echo "make test-gui  the window leg: real Blender 4.3 windows on Xvfb driven by X input (tests/gui/; needs root)"
	@echo "make fuzz-py  hypothesis fuzzing of rokeby_native and the file readers (FUZZ_PY_EXAMPLES=500)"

# --- bootstrap -------------------------------------------------------------------------------
$(VENV)/.deps: requirements.txt requirements-test.txt
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	$(PIP) install -q -r requirements.txt
	@# The add-on package `rokeby` (addon/rokeby) is importable from the venv, for scripts and tests.
	@echo "$(CURDIR)/addon" > "$$($(PY) -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')/rokeby_addon.pth"
	@touch $@

venv: $(VENV)/.deps

$(VENV)/.native: $(VENV)/.deps $(RUST_SRC)
	@rm -f target/wheels/rokeby_native-*.whl
	$(VENV)/bin/maturin build --release --quiet -i $(PY) -o target/wheels
	$(PIP) install -q --force-reinstall --no-deps target/wheels/rokeby_native-*.whl
	@touch $@

native: $(VENV)/.native

# --- the two commands ------------------------------------------------------------------------
demo: native dist
	$(PY) -m rokeby.demo

# The Blender 4.2+ extension zip: add-on files at the root, the manifest with the wheel's real
# filename, the wheel under wheels/ (tools/build_extension.py; rewrites the zip only if it changed).
# rokeby_native's is the only wheel: the add-on reads and writes EXRs through it (the pure-Rust
# `exr` crate), never through a second OpenEXR C library inside Blender's process.
dist: native
	$(PY) tools/build_extension.py --wheels target/wheels --out dist

test: cargo-test pytest

cargo-test:
	cargo test -p rokeby-core --quiet

pytest: native
	$(PY) -m pytest -q

# Static checks in their own environment (the Blender API stubs are a fake `bpy` package).
LINT := .venv-lint
$(LINT)/.deps: requirements-lint.txt
	@test -x $(LINT)/bin/python || $(PYTHON) -m venv $(LINT)
	$(LINT)/bin/python -m pip install -q -r requirements-lint.txt
	@touch $@

lint: $(LINT)/.deps
	$(LINT)/bin/ruff check --select E9,F63,F7,F82,F401 addon tests bench tools
	cargo fmt --all --check
	cargo clippy --workspace --all-targets -- -D warnings
	$(LINT)/bin/python tools/api_check.py

# --- the Blender matrix -------------------------------------------------------------
# `make test-blender BPY=4.2.23` runs the whole pytest suite against bpy <version> in its own venv,
# .venv-bpy-<version>, made idempotently like .venv: BPY_PYTHON, bpy==<version>, the numpy that bpy
# needs (BPY_NUMPY: 1.26.4 up to 5.0; for 5.1+ the one bpy's own requirements pick, unless set) and
# requirements-test.txt, then the rokeby_native wheel that `make native` built (the same abi3 wheel
# the extension zip ships). bpy 4.2-5.0 run on this machine's CPython 3.11. bpy 5.1 and later are
# built for CPython 3.13 only: they run inside tools/py313, a Debian 13 root with its python3.13 made
# once in .py313/ (BPY_RUN; the project folder is bound at the same path inside, so the venv is the
# project's .venv-bpy-<version> on both sides).
BPY        ?= 4.2.23
BPY_CP311  := $(filter 4.% 5.0 5.0.%,$(BPY))
BPY_RUN    ?= $(if $(BPY_CP311),,tools/py313)
BPY_PYTHON ?= $(if $(BPY_CP311),python3,python3.13)
BPY_NUMPY  ?= $(if $(BPY_CP311),1.26.4,)
BPY_VENV   := .venv-bpy-$(BPY)
BPY_PY     := $(BPY_VENV)/bin/python
PYTEST_ARGS ?= -q

$(BPY_VENV)/.deps: requirements-test.txt
	$(if $(BPY_RUN),$(BPY_RUN) --setup)
	@test -e $(BPY_VENV)/pyvenv.cfg || $(BPY_RUN) $(BPY_PYTHON) -m venv $(BPY_VENV)
	$(BPY_RUN) $(BPY_PY) -m pip install -q --upgrade pip
	$(BPY_RUN) $(BPY_PY) -m pip install -q "bpy==$(BPY)" $(if $(BPY_NUMPY),"numpy==$(BPY_NUMPY)") -r requirements-test.txt
	@echo "$(CURDIR)/addon" > "$$($(BPY_RUN) $(BPY_PY) -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')/rokeby_addon.pth"
	@$(BPY_RUN) $(BPY_PY) -c 'import bpy, sys; v = bpy.app.version_string; print("bpy", v, "on Python", sys.version.split()[0]); sys.exit(not v.startswith("$(BPY)".rsplit(".", 1)[0]))'
	@touch $@

test-blender: native $(BPY_VENV)/.deps
	$(BPY_RUN) $(BPY_PY) -m pip install -q --force-reinstall --no-deps target/wheels/rokeby_native-*.whl
	$(BPY_RUN) $(BPY_PY) -m pytest $(PYTEST_ARGS)

# Every leg CI runs after `make test` (4.5 LTS): the newest 5.x, the other LTS and 5.0. Legs on
# CPython 3.11 (bpy up to 5.0) run the tests marked `blender` (MATRIX_CP311_ARGS): the others never
# import bpy, and run on the same CPython, numpy and wheel in `make test` already. Legs on CPython
# 3.13 (5.1+) run every test: there the Python and numpy differ too. MATRIX_JOBS legs run at once
# (mostly one busy core each; two legs on two cores took 15 min where one alone took 12), each leg's
# output printed when it ends; every leg runs to the end, the target fails if any did, and prints
# what each cost.
MATRIX ?= 5.3.0 4.2.23 5.0.1
MATRIX_CP311_ARGS ?= -q -m blender
MATRIX_JOBS ?= 2
test-matrix: native
	@s=$$(date +%s); \
	$(MAKE) --no-print-directory -k -j$(MATRIX_JOBS) --output-sync=target $(addprefix matrix-leg-,$(MATRIX)); rc=$$?; \
	echo "== matrix ($(MATRIX), $(MATRIX_JOBS) at once): $$(( $$(date +%s) - s )) s"; \
	exit $$rc

matrix-leg-%:
	@s=$$(date +%s); \
	case $* in 4.*|5.0|5.0.*) args="$(MATRIX_CP311_ARGS)";; *) args="$(PYTEST_ARGS)";; esac; \
	$(MAKE) --no-print-directory test-blender BPY=$* PYTEST_ARGS="$$args"; rc=$$?; \
	echo "== leg bpy $*: $$(( $$(date +%s) - s )) s$$( [ $$rc = 0 ] || echo ', FAILED')"; \
	exit $$rc

# What .ci/run's second phase runs, CI_JOBS at once (the longest first): the first matrix leg, the
# whole suite on 4.5 (`make pytest`), the other legs, the window leg (its root made in phase 1), then
# lint; each prints its cost.
ci-phase2: $(addprefix matrix-leg-,$(firstword $(MATRIX))) timed-pytest $(addprefix matrix-leg-,$(wordlist 2,99,$(MATRIX))) timed-test-gui timed-lint

timed-%:
	@s=$$(date +%s); \
	$(MAKE) --no-print-directory $*; rc=$$?; \
	echo "== make $*: $$(( $$(date +%s) - s )) s$$( [ $$rc = 0 ] || echo ', FAILED')"; \
	exit $$rc

# --- the window leg (tests/gui/) ----------------------------------------------------------------
# Real Blender windows (Debian 13's blender 4.3 on Xvfb, Mesa's llvmpipe) driven by X input events,
# inside tools/guiroot's own Debian root (.gui-root/, made once: debootstrap + apt-get, needs root).
# Each test installs dist/'s zip from disk into a fresh user configuration; results and screenshots
# go to target/gui/<scenario>/. `make test` never collects tests/gui (tests/conftest.py).
GUI_PYTEST_ARGS ?= -q
gui-root:
	tools/guiroot --setup

test-gui: dist
	$(PY) -m pytest tests/gui $(GUI_PYTEST_ARGS)

# Peers of the benchmark (exact MMP geodesics, potpourri3d, libigl, matplotlib) live in their
# own environment: they need numpy >= 2, bpy 4.5 needs numpy < 2.
PEERS := .venv-peers
$(PEERS)/.deps: requirements-peers.txt
	@test -x $(PEERS)/bin/python || $(PYTHON) -m venv $(PEERS)
	$(PEERS)/bin/python -m pip install -q --upgrade pip
	$(PEERS)/bin/python -m pip install -q -r requirements-peers.txt
	@touch $@

bench: native $(PEERS)/.deps
	$(PY) bench/run.py --peers $(PEERS)/bin/python

# Fuzzing: every rokeby-core entry point for FUZZ_SECONDS each with cargo-fuzz
# (libFuzzer), installed into .tools on first use. The stable toolchain runs it with
# RUSTC_BOOTSTRAP=1 and no sanitizer; a crash leaves its input under rust/fuzz/artifacts.
FUZZ_SECONDS ?= 30
FUZZ_TARGETS := field polar geodesic region sh reconstruct recomposite envmap prefilter silhouette bvh mls2d shadow_mesh shadow_editor rgbe
CARGO_FUZZ := $(CURDIR)/.tools/bin/cargo-fuzz
$(CARGO_FUZZ):
	cargo install --locked --root $(CURDIR)/.tools cargo-fuzz@0.13.2

fuzz: $(CARGO_FUZZ)
	@set -e; for t in $(FUZZ_TARGETS); do \
		echo "== fuzz $$t ($(FUZZ_SECONDS) s)"; \
		RUSTC_BOOTSTRAP=1 $(CARGO_FUZZ) fuzz run --fuzz-dir rust/fuzz --sanitizer none --release $$t -- -max_total_time=$(FUZZ_SECONDS) -rss_limit_mb=2048; \
	done

# Hypothesis fuzzing of every rokeby_native function and method and the bpy-free file
# readers, FUZZ_PY_EXAMPLES examples each, random seeds, in a subprocess under a 4 GiB address-space
# limit with ROKEBY_MAX_ALLOC_BYTES at 1 GiB (tests/native/fuzz/run_fuzz.py). `make test` runs it briefly
# with fixed seeds (tests/native/test_fuzz_native.py).
FUZZ_PY_EXAMPLES ?= 500
fuzz-py: native
	FUZZ_PY_RANDOM=1 $(PY) tests/native/fuzz/run_fuzz.py --examples $(FUZZ_PY_EXAMPLES)

clean:
	rm -rf $(VENV) $(PEERS) $(LINT) .venv-bpy-* .py313 target dist out .tools rust/fuzz/target
