# loomlight -- make targets. `make demo` and `make test` work from a fresh clone; `make help` lists every target
# (from the `## ...` comment on each target's line). The experiments (sweeps, studies, agreement, Table 1) are in
# make/experiments.mk, included at the end.
SHELL := /bin/bash
PY ?= python3
VENV := .venv
# the artifact format: an artifact made before a change to it is refused by its readers, so the first
# artifact of every chain depends on it and the chain is rebuilt
ARTIFACT_FORMAT := pipeline/artifacts.py pipeline/artifact_checks.py
# the code a precompute's or a bysdf fit's output depends on (a change to it remakes them)
PRECOMPUTE_DEPS = $(wildcard stages/precompute/*.py stages/precompute/*/*.py) pipeline/limits.py
FIT_DEPS = pipeline/runners/fit_bysdf.py $(wildcard stages/render/*.py stages/render/*/*.py stages/core/yarn/*.py \
	stages/core/shading/bysdf.py stages/core/shading/microfacet.py)
BIN := $(VENV)/bin
LL := $(BIN)/loomlight
# numba cache root; stages/__init__.py keys it by a hash of the kernel sources
export LOOMLIGHT_NUMBA_CACHE_ROOT := $(CURDIR)/.numba_cache
export MPLBACKEND := Agg
export PYTHONHASHSEED := 0
OUT ?= out/demo
SCENE ?= data/scenes/demo.toml
TILING ?= data/tilings/damask.toml
DAMASK_SCENE ?= data/scenes/draped_damask.toml
# make demo is a first look within minutes on an idle 2-core machine from a fresh clone (README: Two commands):
# every stage and every method, pictures of 160x120 (the scenes' cameras say 320x240: DEMO_SIZE= renders those)
# without refinement, precomputes and fits reduced further than make demo-full's (FULL_*, below). make demo-full
# is the same at 240x180 with adaptive refinement (a second pass gives a pixel up to MAX_SPP more samples, as many
# as its neighbours' relative error asks for to reach render.target_error) into out/demo-full: the README's
# picture. The evaluation set is smaller because procedural volpath without the fibre cache is slow.
DEMO_SIZE ?= --width 160 --height 120
SPP ?= 4
FIBERPATH_SPP ?= 8
MAX_SPP ?= 0
EVAL_W ?= 48
EVAL_H ?= 36
EVAL_SPP ?= 4

# Khungurn et al. 2017 precompute of the damask's two exemplars (README: Precomputed light transport). make demo-full
# and the comparisons (FULL_SVF_ARGS, FULL_IIRTF_ARGS): SVF images of 64x64 (the paper: 128x128), 48 PCA components;
# IIRTF at cells of 3 mean free paths (the paper: 1-2), 200 paths per cell (the paper: 50,000) with the MIS
# estimator, SH order 4; make demo: SVF 32x32, 16 components, IIRTF at cells of 4, 100 paths, SH order 3. make
# prt-sweep uses the paper's SVF and cells of 1.5 mean free paths (PRT_SVF_ARGS, PRT_IIRTF_ARGS): 3.5 points less
# error against fiberpath than cells of 3 (README: Rendering with precomputed transport), 3x the paths. The IIRTF
# holds light from below the cloth too (the paper's extension to bottom surfaces: the drape's hanging sides).
SVF_ARGS ?= --resolution 32 --components 16
IIRTF_ARGS ?= --order 3 --cell-factor 4 --paths 100 --light-sampling mis --light-domain sphere
FULL_SVF_ARGS ?= --resolution 64 --components 48
FULL_IIRTF_ARGS ?= --order 4 --cell-factor 3 --paths 200 --light-sampling mis --light-domain sphere

# Daubert et al. 2001 in the demo: the damask's ground exemplar fitted as a cloth texture, reduced (the defaults: 32 x 32
# texels, 8x8 views and lights, 16 rays) and dressed on the draped cloth
BTF_ARGS ?= --resolution 8 --views 4x8 --lights 4x8 --spp 4 --model tabulated
FULL_BTF_ARGS ?= --resolution 16 --views 6x8 --lights 6x8 --spp 8 --model tabulated

# the multi-scale yarn model in the demo: the yarn-level model fitted to fiberpath (front / back / both lights, small renders) on
# the demo swatch and on the knitted swatch (data/scenes/knit.toml: its own yarn colour and fleece BCSDF), the
# knit rendered with bysdf beside fiberpath on its realized fibres, and the woven swatch in the evaluation set
KNIT_SCENE ?= data/scenes/knit.toml
FIT_ARGS ?= --width 48 --height 36 --spp 8 --ref-spp 16 --iterations 3
FULL_FIT_ARGS ?= --width 64 --height 48 --spp 16 --ref-spp 32 --iterations 6

# make demo-full: make demo with these
FULL_OUT ?= out/demo-full
FULL_VARS = OUT=$(FULL_OUT) DEMO_SIZE="--width 240 --height 180" SPP=8 FIBERPATH_SPP=16 MAX_SPP=128 EVAL_W=64 \
	EVAL_H=48 EVAL_SPP=8 SVF_ARGS="$(FULL_SVF_ARGS)" IIRTF_ARGS="$(FULL_IIRTF_ARGS)" BTF_ARGS="$(FULL_BTF_ARGS)" \
	FIT_ARGS="$(FULL_FIT_ARGS)"

TWILL_SCENE ?= data/scenes/twill_swatch.toml
# what the experiments (make/experiments.mk) and the comparisons share: the Khungurn et al. 2017 flat patches and damask
# precomputed at the paper's settings (out/prt) and the Daubert et al. 2001 textures of the flat patches (out/btf)
PRT := out/prt
BTF_DIR := out/btf

# --- which method gives the right picture fastest: every method against a converged reference, error against
# time (loomlight evaluate --convergence; data/compare/*.toml; README: Choosing a method). make references
# renders each comparison's reference until its noise is within the file's targets (kept under
# $(COMPARE)/<name>/reference, reused while scene, settings and code are unchanged; never by make test);
# make compare renders every method at its budgets and writes $(COMPARE)/<name>/report.html and the summary. Their
# fibres, tables and tilings are make demo's (no settings); their precomputes and fits are their own, at make
# demo-full's settings ($(COMPARE_IN))
COMPARE := out/compare
COMPARE_FILES ?= $(filter-out data/compare/demo_quick.toml,$(wildcard data/compare/*.toml))
COMPARE_ARGS ?=
COMPARE_IN := $(COMPARE)/inputs
COMPARE_INPUTS = $(OUT)/fibers.zarr/zarr.json $(OUT)/tables.zarr/zarr.json $(COMPARE_IN)/bysdf_fit.toml \
	$(COMPARE_IN)/damask_svf.zarr/zarr.json $(COMPARE_IN)/damask_iirtf.zarr/zarr.json \
	$(COMPARE_IN)/damask_btf_fit.zarr/zarr.json $(OUT)/knit_fibers.zarr/zarr.json $(COMPARE_IN)/knit_bysdf_fit.toml \
	$(COMPARE_IN)/twill_fibers.zarr/zarr.json $(COMPARE_IN)/knit_btf.zarr/zarr.json \
	$(COMPARE_IN)/knit_btf_through.zarr/zarr.json $(COMPARE_IN)/damask_btf_surface.zarr/zarr.json \
	$(COMPARE_IN)/damask_svf_full.zarr/zarr.json $(COMPARE_IN)/damask_iirtf_full.zarr/zarr.json \
	$(PRT)/flat41_svf.zarr/zarr.json $(PRT)/flat41_iirtf.zarr/zarr.json $(BTF_DIR)/flat41_btf.zarr/zarr.json

.DEFAULT_GOAL := help
.PHONY: help setup demo demo-full test test-all lint bench compile-report references compare docs clean FORCE

##@ Main targets

help: ## list every target with what it does (this list)
	@echo "usage: make TARGET [VARIABLE=value ...]  (variables: the top of Makefile and make/experiments.mk)"
	@awk 'BEGIN { FS = ":[^#]*## " } \
	    /^##@ / { printf "\n%s\n", substr($$0, 5); next } \
	    /^[a-zA-Z0-9][a-zA-Z0-9_.-]*:[^=]*## / { printf "  make %-14s %s\n", $$1, $$2 }' $(MAKEFILE_LIST)

setup: $(VENV)/.installed ## create .venv and install loomlight with its test and Dask dependencies

# two stages at a time, their lines interleaved as they come (progress and compile notices live, as plain
# lines off a terminal);
# the tables and fibres first, so the longest chain (procedural volpath, the longest compilation on a
# cold cache) starts at once beside the rest; the knit's fibres after the demo's (two realize commands at
# once would both compile realize's kernels on a cold cache: make compile-report)
demo: $(VENV)/.installed ## set up .venv if needed, every stage and method on the bundled scenes (small, a first look), print the output paths
	@$(MAKE) --no-print-directory -j$(DEMO_JOBS) --output-sync=line $(OUT)/tables.zarr/zarr.json $(OUT)/fibers.zarr/zarr.json
	@$(MAKE) --no-print-directory -j$(DEMO_JOBS) --output-sync=line demo-outputs
	@$(MAKE) --no-print-directory $(OUT)/compare/report.md
	@echo "demo outputs:"
	@echo "  which method, at equal error: $(OUT)/compare/report.html ($(OUT)/compare/convergence.png)"
	@echo "  yarn curves          : $(OUT)/yarns.zarr ($(OUT)/yarns.png)"
	@echo "  procedural tables    : $(OUT)/tables.zarr (cross-section $(OUT)/cross_section.png)"
	@echo "  realized fibres      : $(OUT)/fibers.zarr ($(OUT)/fibers.png)"
	@echo "  volpath render       : $(OUT)/volpath.exr ($(OUT)/volpath.png)"
	@echo "  fiberpath render     : $(OUT)/fiberpath.exr ($(OUT)/fiberpath.png)"
	@echo "  damask tiling        : $(OUT)/damask_tiling.zarr ($(OUT)/damask_tiling.png)"
	@echo "  draped damask render : $(OUT)/damask.exr ($(OUT)/damask.png)"
	@echo "  damask SVF (Khungurn et al. 2017): $(OUT)/damask_svf.zarr ($(OUT)/damask_svf.png)"
	@echo "  damask IIRTF         : $(OUT)/damask_iirtf.zarr ($(OUT)/damask_iirtf.png)"
	@echo "  damask, prt (Khungurn et al. 2017): $(OUT)/damask_prt.exr ($(OUT)/damask_prt.png)"
	@echo "  damask texture (Daubert et al. 2001): $(OUT)/damask_btf_fit.zarr ($(OUT)/damask_btf_fit.png)"
	@echo "  damask, btf (Daubert et al. 2001): $(OUT)/damask_btf.exr ($(OUT)/damask_btf.png)"
	@echo "  damask, btf's tabulated model: $(OUT)/damask_btf_tabulated.exr ($(OUT)/damask_btf_tabulated.png)"
	@echo "  prt, btf vs fiberpath: $(OUT)/eval/damask/report.md ($(OUT)/eval/damask/report.html)"
	@echo "  bysdf fitted to fiberpath (A Multi-scale Yarn Appearance Model with Fiber Details): $(OUT)/bysdf_fit.toml, $(OUT)/knit_bysdf_fit.toml (.json reports)"
	@echo "  knit, bysdf (A Multi-scale Yarn Appearance Model with Fiber Details): $(OUT)/knit_bysdf.exr ($(OUT)/knit_bysdf.png)"
	@echo "  knit, fiberpath      : $(OUT)/knit_fiberpath.exr ($(OUT)/knit_fiberpath.png)"
	@echo "  knit, bysdf vs fiberpath: $(OUT)/eval/knit/report.md ($(OUT)/eval/knit/report.html)"
	@echo "  evaluation report    : $(OUT)/eval/report/report.md ($(OUT)/eval/report/report.html)"

demo-full: ## the demo at 240x180 with adaptive refinement and larger precomputes (out/demo-full; the README's picture)
	@$(MAKE) --no-print-directory demo $(FULL_VARS)

# make test: everything but the tests marked slow; make test-all: all of them
test: $(VENV)/.installed ## set up .venv if needed, run the test suite but the slow tests
	$(BIN)/python -m pytest -q -n 2 --dist loadfile -m "not slow"

test-all: $(VENV)/.installed ## the whole test suite, the slow tests too
	$(BIN)/python -m pytest -q -n 2 --dist loadfile

# the rules and their exceptions: pyproject.toml [tool.ruff]; .ci/run runs it before make test
lint: $(VENV)/.installed ## ruff over the code, tests and benchmarks (pyflakes, pycodestyle, isort, bugbear)
	$(BIN)/ruff check .

# on empty numba caches of its own (the checkout's cache and out/ untouched); COMPILE_REPORT_ARGS="--demo full"
# measures make demo-full's commands instead, "--tests all" make test's whole suite
compile-report: $(VENV)/.installed ## what numba compiles on a cold cache for the demo and the heaviest tests -> bench/results/compile.json
	$(BIN)/python bench/compile_report.py $(COMPILE_REPORT_ARGS)
	$(LL) docs --only measurements --bench-results bench/results --compare-dir $(COMPARE)

# the benchmarks' exit status is make bench's, after docs/measurements.md is rewritten from what they wrote
bench: $(VENV)/.installed ## benchmarks -> bench/results/*.json, bench/results/summary.md, docs/measurements.md
	@mkdir -p bench/results
	@# the optional peer renderer for bench_mitsuba (skipped with a message when it cannot be installed)
	@$(PIP) install -q -e '.[test,dask,bench]' > $(VENV)/pip-bench.log 2>&1 || echo "note: Mitsuba 3 not installed (see $(VENV)/pip-bench.log); bench_mitsuba will be skipped"
	$(BIN)/python bench/run.py --out bench/results; status=$$?; \
	    $(LL) docs --only measurements --bench-results bench/results --compare-dir $(COMPARE) && exit $$status

references: $(COMPARE_INPUTS) ## render each comparison's converged reference (data/compare/*.toml; kept and reused)
	@for f in $(COMPARE_FILES); do \
	    $(LL) evaluate --convergence $$f -o $(COMPARE)/$$(basename $$f .toml) --reference-only || exit 1; \
	done

compare: references ## every method against the converged references, error against time (out/compare, docs/measurements.md)
	@for f in $(COMPARE_FILES); do \
	    $(LL) evaluate --convergence $$f -o $(COMPARE)/$$(basename $$f .toml) $(COMPARE_ARGS) || exit 1; \
	done
	@for f in $(COMPARE_FILES); do echo "report: $(COMPARE)/$$(basename $$f .toml)/report.html"; done
	$(LL) docs --only measurements --bench-results bench/results --compare-dir $(COMPARE)

docs: $(VENV)/.installed ## regenerate docs/scenes.md, the method pages' generated blocks and docs/measurements.md
	$(LL) docs

clean: ## remove out/, the numba cache and pytest's cache
	rm -rf out .numba_cache .pytest_cache

# pip's output goes to .venv/pip.log and is shown only when the install fails. The venv's own pip (python 3.11's,
# 23.x) installs editable projects; --no-compile leaves byte-compiling to the first import, which then compiles
# only the modules loomlight uses (of 7,400 files in the dependencies)
PIP := $(BIN)/python -m pip --disable-pip-version-check --no-input
$(VENV)/.installed: pyproject.toml
	@test -x $(BIN)/python || { echo "creating $(VENV) (python3 -m venv)"; $(PY) -m venv $(VENV); }
	@echo "installing loomlight and its dependencies into $(VENV) (log: $(VENV)/pip.log)"
	@{ $(PIP) install -q --no-compile -e '.[test,dask]'; } > $(VENV)/pip.log 2>&1 \
	    || { cat $(VENV)/pip.log; echo "error: pip install failed (log above, also in $(VENV)/pip.log)"; exit 1; }
	@touch $@

# --- one rule per stage artifact; the CLI itself skips a stage whose inputs and code are unchanged ---
$(OUT)/yarns.zarr/zarr.json: $(SCENE) $(VENV)/.installed $(ARTIFACT_FORMAT)
	$(LL) ingest $(SCENE) -o $(OUT)/yarns.zarr

$(OUT)/tables.zarr/zarr.json: $(OUT)/yarns.zarr/zarr.json $(wildcard stages/procedural/*.py)
	$(LL) tables $(OUT)/yarns.zarr -o $(OUT)/tables.zarr

$(OUT)/fibers.zarr/zarr.json: $(OUT)/yarns.zarr/zarr.json $(wildcard stages/procedural/*.py)
	$(LL) realize $(OUT)/yarns.zarr -o $(OUT)/fibers.zarr

# An artifact's arguments as its prerequisite ($(ARGS_DIR)/NAME.args, from ARGS_NAME): the recipe runs every
# time but rewrites the file only when the arguments differ from those it holds, so a changed IIRTF_ARGS (on
# the command line, or in a newer Makefile) rebuilds that artifact, and the same arguments rebuild nothing
# (`make -n` cannot know without running it, and lists those artifacts as to be made)
ARGS_DIR = $(OUT)/.args
ARGS_damask_svf = $(SVF_ARGS)
ARGS_damask_iirtf = $(IIRTF_ARGS)
ARGS_damask_btf = $(BTF_ARGS)
ARGS_bysdf_fit = $(FIT_ARGS)
ARGS_damask_svf_full = $(PRT_SVF_ARGS)
ARGS_damask_iirtf_full = $(PRT_DAMASK_IIRTF_ARGS)
ARGS_cmp_damask_svf = $(FULL_SVF_ARGS)
ARGS_cmp_damask_iirtf = $(FULL_IIRTF_ARGS)
ARGS_cmp_damask_btf = $(FULL_BTF_ARGS)
ARGS_cmp_bysdf_fit = $(FULL_FIT_ARGS)

$(ARGS_DIR)/%.args: FORCE
	@mkdir -p $(@D); printf '%s\n' '$(ARGS_$*)' | cmp -s - $@ || printf '%s\n' '$(ARGS_$*)' > $@

FORCE:

$(OUT)/damask_tiling.zarr/zarr.json: $(TILING) data/tilings/damask_motif.png $(DAMASK_SCENE) $(VENV)/.installed $(ARTIFACT_FORMAT)
	$(LL) tile $(TILING) -o $(OUT)/damask_tiling.zarr

$(OUT)/damask_svf.zarr/zarr.json: $(OUT)/damask_tiling.zarr/zarr.json $(PRECOMPUTE_DEPS) $(ARGS_DIR)/damask_svf.args
	$(LL) precompute svf $(OUT)/damask_tiling.zarr -o $(OUT)/damask_svf.zarr $(SVF_ARGS)

$(OUT)/damask_iirtf.zarr/zarr.json: $(OUT)/damask_tiling.zarr/zarr.json $(DAMASK_SCENE) $(PRECOMPUTE_DEPS) pipeline/runners/precompute.py $(ARGS_DIR)/damask_iirtf.args
	$(LL) precompute iirtf $(OUT)/damask_tiling.zarr -o $(OUT)/damask_iirtf.zarr $(IIRTF_ARGS)

# --- pictures of intermediate artifacts ---
$(OUT)/yarns.png: $(OUT)/yarns.zarr/zarr.json
	$(LL) inspect $(OUT)/yarns.zarr --png $@ --frames

$(OUT)/cross_section.png: $(OUT)/tables.zarr/zarr.json
	$(LL) inspect $(OUT)/tables.zarr --png $@

$(OUT)/fibers.png: $(OUT)/fibers.zarr/zarr.json
	$(LL) inspect $(OUT)/fibers.zarr --png $@ --yarn 0

$(OUT)/damask_tiling.png: $(OUT)/damask_tiling.zarr/zarr.json
	$(LL) inspect $(OUT)/damask_tiling.zarr --png $@ --width 1200 --height 600

$(OUT)/damask_svf.png: $(OUT)/damask_svf.zarr/zarr.json
	$(LL) inspect $(OUT)/damask_svf.zarr --png $@

$(OUT)/damask_iirtf.png: $(OUT)/damask_iirtf.zarr/zarr.json
	$(LL) inspect $(OUT)/damask_iirtf.zarr --png $@

# --- renders (EXR + PNG preview + render artifact with statistics) ---
# the main volpath picture: procedural lookups with the render-time fibre cache (--cache, default 2048 MiB)
$(OUT)/volpath.exr: $(OUT)/tables.zarr/zarr.json $(SCENE)
	$(LL) render $(SCENE) --method volpath --source procedural --tables $(OUT)/tables.zarr --spp $(SPP) \
	    --max-spp $(MAX_SPP) $(DEMO_SIZE) -o $@

$(OUT)/fiberpath.exr: $(OUT)/fibers.zarr/zarr.json $(SCENE)
	$(LL) render $(SCENE) --method fiberpath --fibers $(OUT)/fibers.zarr --spp $(FIBERPATH_SPP) --max-spp $(MAX_SPP) $(DEMO_SIZE) -o $@

$(OUT)/damask.exr: $(OUT)/damask_tiling.zarr/zarr.json $(DAMASK_SCENE)
	$(LL) render $(DAMASK_SCENE) --method fiberpath --fibers $(OUT)/damask_tiling.zarr --spp $(FIBERPATH_SPP) --max-spp $(MAX_SPP) $(DEMO_SIZE) -o $@

$(OUT)/damask_prt.exr: $(OUT)/damask_svf.zarr/zarr.json $(OUT)/damask_iirtf.zarr/zarr.json $(DAMASK_SCENE)
	$(LL) render $(DAMASK_SCENE) --method prt --fibers $(OUT)/damask_tiling.zarr --set svf=$(OUT)/damask_svf.zarr \
	    --set iirtf=$(OUT)/damask_iirtf.zarr --spp $(FIBERPATH_SPP) --max-spp $(MAX_SPP) $(DEMO_SIZE) -o $@

$(OUT)/damask_btf_fit.zarr/zarr.json: $(OUT)/damask_tiling.zarr/zarr.json $(DAMASK_SCENE) $(PRECOMPUTE_DEPS) pipeline/runners/precompute_btf.py $(ARGS_DIR)/damask_btf.args
	$(LL) precompute btf $(OUT)/damask_tiling.zarr -o $(OUT)/damask_btf_fit.zarr $(BTF_ARGS)

$(OUT)/damask_btf_fit.png: $(OUT)/damask_btf_fit.zarr/zarr.json
	$(LL) inspect $(OUT)/damask_btf_fit.zarr --png $@

$(OUT)/damask_btf.exr: $(OUT)/damask_btf_fit.zarr/zarr.json $(DAMASK_SCENE)
	$(LL) render $(DAMASK_SCENE) --method btf --source tiling --fibers $(OUT)/damask_tiling.zarr \
	    --set btf=$(OUT)/damask_btf_fit.zarr --spp $(SPP) $(DEMO_SIZE) -o $@

$(OUT)/damask_btf_tabulated.exr: $(OUT)/damask_btf_fit.zarr/zarr.json $(DAMASK_SCENE)
	$(LL) render $(DAMASK_SCENE) --method btf --source tiling --fibers $(OUT)/damask_tiling.zarr \
	    --set btf=$(OUT)/damask_btf_fit.zarr --set model=tabulated --spp $(SPP) $(DEMO_SIZE) -o $@

$(OUT)/bysdf_fit.toml: $(OUT)/fibers.zarr/zarr.json $(SCENE) $(FIT_DEPS) $(ARGS_DIR)/bysdf_fit.args
	$(LL) fit-bysdf $(SCENE) --yarns $(OUT)/yarns.zarr --fibers $(OUT)/fibers.zarr -o $@ $(FIT_ARGS)

$(OUT)/knit_yarns.zarr/zarr.json: $(KNIT_SCENE) $(VENV)/.installed $(ARTIFACT_FORMAT)
	$(LL) ingest $(KNIT_SCENE) -o $(OUT)/knit_yarns.zarr

$(OUT)/knit_fibers.zarr/zarr.json: $(OUT)/knit_yarns.zarr/zarr.json $(wildcard stages/procedural/*.py)
	$(LL) realize $(OUT)/knit_yarns.zarr -o $(OUT)/knit_fibers.zarr

$(OUT)/knit_bysdf_fit.toml: $(OUT)/knit_fibers.zarr/zarr.json $(KNIT_SCENE) $(FIT_DEPS) $(ARGS_DIR)/bysdf_fit.args
	$(LL) fit-bysdf $(KNIT_SCENE) --yarns $(OUT)/knit_yarns.zarr --fibers $(OUT)/knit_fibers.zarr -o $@ $(FIT_ARGS)

$(OUT)/knit_bysdf.exr: $(OUT)/knit_yarns.zarr/zarr.json $(OUT)/knit_bysdf_fit.toml $(KNIT_SCENE)
	$(LL) render $(KNIT_SCENE) --method bysdf --set yarns=$(OUT)/knit_yarns.zarr --set params=$(OUT)/knit_bysdf_fit.toml \
	    --spp $(FIBERPATH_SPP) $(DEMO_SIZE) -o $@

$(OUT)/knit_fiberpath.exr: $(OUT)/knit_fibers.zarr/zarr.json $(KNIT_SCENE)
	$(LL) render $(KNIT_SCENE) --method fiberpath --fibers $(OUT)/knit_fibers.zarr --spp $(FIBERPATH_SPP) \
	    $(DEMO_SIZE) -o $@

$(OUT)/eval/knit/report.md: $(OUT)/knit_fiberpath.exr $(OUT)/knit_bysdf.exr
	$(LL) evaluate --ref $(OUT)/knit_fiberpath.exr --test $(OUT)/knit_bysdf.exr -o $(OUT)/eval/knit

# precomputed light transport and the fitted texture against their reference on the same view, error maps
# and times
$(OUT)/eval/damask/report.md: $(OUT)/damask.exr $(OUT)/damask_prt.exr $(OUT)/damask_btf.exr $(OUT)/damask_btf_tabulated.exr
	$(LL) evaluate --ref $(OUT)/damask.exr --test $(OUT)/damask_prt.exr --test $(OUT)/damask_btf.exr \
	    --test $(OUT)/damask_btf_tabulated.exr -o $(OUT)/eval/damask

# --- evaluation set: the same view, small, procedural vs realized volpath and fiberpath ---
# (the procedural render with --cache 0: every point answered by the exact lookups, not by cached fibres)
EVAL_ARGS = --width $(EVAL_W) --height $(EVAL_H) --spp $(EVAL_SPP)
$(OUT)/eval/volpath-procedural.exr: $(OUT)/tables.zarr/zarr.json $(SCENE)
	$(LL) render $(SCENE) --method volpath --source procedural --tables $(OUT)/tables.zarr --cache 0 $(EVAL_ARGS) -o $@

$(OUT)/eval/volpath-realized.exr: $(OUT)/fibers.zarr/zarr.json $(SCENE)
	$(LL) render $(SCENE) --method volpath --source realized --fibers $(OUT)/fibers.zarr $(EVAL_ARGS) -o $@

$(OUT)/eval/fiberpath.exr: $(OUT)/fibers.zarr/zarr.json $(SCENE)
	$(LL) render $(SCENE) --method fiberpath --fibers $(OUT)/fibers.zarr $(EVAL_ARGS) -o $@

$(OUT)/eval/bysdf.exr: $(OUT)/yarns.zarr/zarr.json $(OUT)/bysdf_fit.toml $(SCENE)
	$(LL) render $(SCENE) --method bysdf --set yarns=$(OUT)/yarns.zarr --set params=$(OUT)/bysdf_fit.toml $(EVAL_ARGS) -o $@

$(OUT)/eval/report/report.md: $(OUT)/eval/volpath-procedural.exr $(OUT)/eval/volpath-realized.exr $(OUT)/eval/fiberpath.exr \
	    $(OUT)/eval/bysdf.exr
	$(LL) evaluate --ref $(OUT)/eval/volpath-realized.exr --test $(OUT)/eval/volpath-procedural.exr \
	    --test $(OUT)/eval/fiberpath.exr --test $(OUT)/eval/bysdf.exr -o $(OUT)/eval/report

# make demo's equal-error comparison, last and alone (its render times are measured on an idle machine; a reference
# made by other code is rebuilt first): the demo swatch at 48x36, fiberpath and bysdf at three budgets each against
# a reference of at least 512 spp (data/compare/demo_quick.toml)
$(OUT)/compare/report.md: $(OUT)/fibers.zarr/zarr.json $(OUT)/bysdf_fit.toml data/compare/demo_quick.toml
	$(LL) evaluate --convergence data/compare/demo_quick.toml -o $(OUT)/compare --reference-only
	$(LL) evaluate --convergence data/compare/demo_quick.toml -o $(OUT)/compare

# the longest chains first: with DEMO_JOBS stages at a time, numba compilation (one core) overlaps
# another stage's two-thread work
DEMO_OUTPUTS = $(OUT)/eval/report/report.md $(OUT)/damask_prt.exr $(OUT)/eval/damask/report.md $(OUT)/eval/knit/report.md \
	$(OUT)/volpath.exr $(OUT)/fiberpath.exr $(OUT)/damask.exr \
	$(OUT)/yarns.png $(OUT)/cross_section.png $(OUT)/fibers.png $(OUT)/damask_tiling.png \
	$(OUT)/damask_svf.png $(OUT)/damask_iirtf.png $(OUT)/damask_btf_fit.png
DEMO_JOBS ?= 2

.PHONY: demo-outputs
demo-outputs: $(DEMO_OUTPUTS)

# --- the comparisons' own inputs (make references, make compare; the flat patches come from make/experiments.mk) ---
$(COMPARE_IN)/twill_yarns.zarr/zarr.json: $(TWILL_SCENE) $(VENV)/.installed $(ARTIFACT_FORMAT)
	$(LL) ingest $(TWILL_SCENE) -o $(COMPARE_IN)/twill_yarns.zarr

$(COMPARE_IN)/twill_fibers.zarr/zarr.json: $(COMPARE_IN)/twill_yarns.zarr/zarr.json $(wildcard stages/procedural/*.py)
	$(LL) realize $(COMPARE_IN)/twill_yarns.zarr -o $(COMPARE_IN)/twill_fibers.zarr

# the comparisons' own precomputes and fits, at make demo-full's settings (data/compare/damask.toml, demo.toml,
# demo_delta.toml, knit.toml)
$(COMPARE_IN)/damask_svf.zarr/zarr.json: $(OUT)/damask_tiling.zarr/zarr.json $(PRECOMPUTE_DEPS) $(ARGS_DIR)/cmp_damask_svf.args
	$(LL) precompute svf $(OUT)/damask_tiling.zarr -o $(COMPARE_IN)/damask_svf.zarr $(FULL_SVF_ARGS)

$(COMPARE_IN)/damask_iirtf.zarr/zarr.json: $(OUT)/damask_tiling.zarr/zarr.json $(DAMASK_SCENE) $(PRECOMPUTE_DEPS) pipeline/runners/precompute.py $(ARGS_DIR)/cmp_damask_iirtf.args
	$(LL) precompute iirtf $(OUT)/damask_tiling.zarr -o $(COMPARE_IN)/damask_iirtf.zarr $(FULL_IIRTF_ARGS)

$(COMPARE_IN)/damask_btf_fit.zarr/zarr.json: $(OUT)/damask_tiling.zarr/zarr.json $(DAMASK_SCENE) $(PRECOMPUTE_DEPS) pipeline/runners/precompute_btf.py $(ARGS_DIR)/cmp_damask_btf.args
	$(LL) precompute btf $(OUT)/damask_tiling.zarr -o $(COMPARE_IN)/damask_btf_fit.zarr $(FULL_BTF_ARGS)

# the same texture sampled where its views meet the fibres (damask.toml's btf_surface)
$(COMPARE_IN)/damask_btf_surface.zarr/zarr.json: $(OUT)/damask_tiling.zarr/zarr.json $(DAMASK_SCENE) $(PRECOMPUTE_DEPS) pipeline/runners/precompute_btf.py $(ARGS_DIR)/cmp_damask_btf.args
	$(LL) precompute btf $(OUT)/damask_tiling.zarr -o $(COMPARE_IN)/damask_btf_surface.zarr $(FULL_BTF_ARGS) --plane surface

$(COMPARE_IN)/bysdf_fit.toml: $(OUT)/fibers.zarr/zarr.json $(SCENE) $(FIT_DEPS) $(ARGS_DIR)/cmp_bysdf_fit.args
	$(LL) fit-bysdf $(SCENE) --yarns $(OUT)/yarns.zarr --fibers $(OUT)/fibers.zarr -o $@ $(FULL_FIT_ARGS)

$(COMPARE_IN)/knit_bysdf_fit.toml: $(OUT)/knit_fibers.zarr/zarr.json $(KNIT_SCENE) $(FIT_DEPS) $(ARGS_DIR)/cmp_bysdf_fit.args
	$(LL) fit-bysdf $(KNIT_SCENE) --yarns $(OUT)/knit_yarns.zarr --fibers $(OUT)/knit_fibers.zarr -o $@ $(FULL_FIT_ARGS)

# the draped damask's precompute at the prt sweep's settings (PRT_SVF_ARGS, PRT_DAMASK_IIRTF_ARGS: SVF 128, IIRTF
# cells of 1.5 mean free paths, light from both sides) beside make demo-full's reduced one: data/compare/damask.toml
# compares both
$(COMPARE_IN)/damask_svf_full.zarr/zarr.json: $(OUT)/damask_tiling.zarr/zarr.json $(PRECOMPUTE_DEPS) $(ARGS_DIR)/damask_svf_full.args
	$(LL) precompute svf $(OUT)/damask_tiling.zarr -o $(COMPARE_IN)/damask_svf_full.zarr $(PRT_SVF_ARGS)

$(COMPARE_IN)/damask_iirtf_full.zarr/zarr.json: $(OUT)/damask_tiling.zarr/zarr.json $(DAMASK_SCENE) $(PRECOMPUTE_DEPS) pipeline/runners/precompute.py $(ARGS_DIR)/damask_iirtf_full.args
	$(LL) precompute iirtf $(OUT)/damask_tiling.zarr -o $(COMPARE_IN)/damask_iirtf_full.zarr $(PRT_DAMASK_IIRTF_ARGS)

$(COMPARE_IN)/knit_tiling.zarr/zarr.json: data/tilings/knit_swatch.toml data/scenes/knit_swatch.toml $(VENV)/.installed $(ARTIFACT_FORMAT)
	$(LL) tile data/tilings/knit_swatch.toml -o $(COMPARE_IN)/knit_tiling.zarr

$(COMPARE_IN)/knit_btf.zarr/zarr.json: $(COMPARE_IN)/knit_tiling.zarr/zarr.json $(PRECOMPUTE_DEPS) pipeline/runners/precompute_btf.py
	$(LL) precompute btf $(COMPARE_IN)/knit_tiling.zarr -o $(COMPARE_IN)/knit_btf.zarr --model tabulated

# the same stitch lit from below too, each texel on its own plane, read by relief mapping, 32 rays a texel and view
# (knit_btf.toml's btf_through)
$(COMPARE_IN)/knit_btf_through.zarr/zarr.json: $(COMPARE_IN)/knit_tiling.zarr/zarr.json $(PRECOMPUTE_DEPS) pipeline/runners/precompute_btf.py
	$(LL) precompute btf $(COMPARE_IN)/knit_tiling.zarr -o $(COMPARE_IN)/knit_btf_through.zarr --model tabulated \
	    --light-domain sphere --plane relief --spp 32

.PRECIOUS: $(COMPARE_IN)/%.zarr/zarr.json

include make/experiments.mk
