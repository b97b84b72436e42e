# loomlight — make targets for full runs. `make demo` and `make test` work from a fresh clone.
SHELL := /bin/bash
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
LL := $(BIN)/loomlight
export NUMBA_CACHE_DIR := $(CURDIR)/.numba_cache
export MPLBACKEND := Agg
export PYTHONHASHSEED := 0
OUT ?= out/demo
SCENE ?= data/scenes/demo.toml

.PHONY: setup demo test bench clean help

help:
	@echo "make demo   - set up .venv if needed, run the demo scene end to end, print output paths"
	@echo "make test   - set up .venv if needed, run the test suite"
	@echo "make bench  - run the benchmarks, write bench/results/*.json and bench/results/summary.md"
	@echo "make setup  - create .venv and install loomlight with its test dependencies"

$(VENV)/.installed: pyproject.toml
	@test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	@touch $@

setup: $(VENV)/.installed

# --- demo: one rule per stage artifact; the CLI itself skips a stage whose inputs are unchanged ---
$(OUT)/yarns.zarr/zarr.json: $(SCENE) $(VENV)/.installed
	$(LL) ingest $(SCENE) -o $(OUT)/yarns.zarr

$(OUT)/yarns.png: $(OUT)/yarns.zarr/zarr.json
	$(LL) inspect $(OUT)/yarns.zarr --png $@

demo: $(OUT)/yarns.zarr/zarr.json $(OUT)/yarns.png
	@$(LL) info $(OUT)/yarns.zarr
	@echo "demo outputs:"
	@echo "  yarn curves artifact : $(OUT)/yarns.zarr"
	@echo "  yarn curves picture  : $(OUT)/yarns.png"

test: $(VENV)/.installed
	$(BIN)/python -m pytest -q -n 2 --dist loadfile

bench: $(VENV)/.installed
	@mkdir -p bench/results
	$(BIN)/python bench/run.py --out bench/results

clean:
	rm -rf out .numba_cache .pytest_cache
