# loomlight -- the experiments: Luan et al. 2017 Table 1 at scale, the light sweeps, fiberpath against volpath, the Khungurn et al. 2017
# and Daubert et al. 2001 parameter sweeps and studies. Included by the Makefile (its variables: OUT, SCENE, LL, PRT, BTF_DIR,
# TWILL_SCENE, ...); every target has a `## ...` line that `make help` lists.

##@ Experiments (make/experiments.mk)

LARGE_SCENE ?= data/scenes/woven_large.toml
# make table1's scale row: the 1,000-yarn fabric rendered from its close-up camera, procedural only
# (its full realization, ~74 GB, is counted, never built)
LARGE_CLOSE_SCENE ?= data/scenes/woven_large_close.toml
LARGE_ARGS ?= --width 320 --height 240 --spp 4
LARGE_OUT ?= out/large
# make table1's 10x row: woven_huge (3,200 yarns, 160 cm square, ~750 GB if realized), procedural only,
# from its close-up camera (README, "Scale"). Its tables build and render estimate 19-20 GiB, over the default
# budget (75 % of the available memory): the row allows HUGE_BUDGET MiB, 95 % of the memory available when make
# starts (a smaller machine still refuses)
HUGE_SCENE ?= data/scenes/woven_huge.toml
HUGE_ARGS ?= --width 320 --height 240 --spp 4 --cache 1024
HUGE_OUT ?= out/huge
HUGE_BUDGET ?= $(shell awk '/MemAvailable/ {print int($$2 / 1024 * 0.95)}' /proc/meminfo 2>/dev/null)

# make agreement: both swatches, fiberpath against realized volpath, converged (README: One look)
AGREE ?= out/agreement
AGREE_ARGS ?= --width 128 --height 96 --spp 64

.PHONY: table1 room room-volpath sweep agreement prt-sweep prt-study btf-sweep btf-through btf-azimuth albedo-curves gallery

# --- Luan et al. 2017, Table 1 ---
# woven_large keeps one stored rotation-minimising-frame sample per spline segment (ingest's default is 4):
# those samples are breakpoints of the frame that the lookups' frame samples must keep, so this halves the
# frame samples (8.0 M -> 4.0 M rows) and saves ~0.8 GB when its tables load. The woven generator's yarns are
# planar curves, whose rotation-minimising frame one double reflection per segment gives as four do (normals
# within 2.3e-16 over 9 yarns x 20,000 points, positions identical): the same fabric
LARGE_INGEST_ARGS ?= --frame-samples 1
$(LARGE_OUT)/yarns.zarr/zarr.json: $(LARGE_SCENE) $(VENV)/.installed $(ARTIFACT_FORMAT)
	$(LL) ingest $(LARGE_SCENE) -o $(LARGE_OUT)/yarns.zarr $(LARGE_INGEST_ARGS)

$(LARGE_OUT)/tables.zarr/zarr.json: $(LARGE_OUT)/yarns.zarr/zarr.json $(wildcard stages/procedural/*.py)
	$(LL) tables $(LARGE_OUT)/yarns.zarr -o $(LARGE_OUT)/tables.zarr

$(LARGE_OUT)/close.exr: $(LARGE_OUT)/tables.zarr/zarr.json $(LARGE_CLOSE_SCENE)
	$(LL) render $(LARGE_CLOSE_SCENE) --method volpath --source procedural --tables $(LARGE_OUT)/tables.zarr \
	    $(LARGE_ARGS) -o $@

$(HUGE_OUT)/yarns.zarr/zarr.json: $(HUGE_SCENE) $(VENV)/.installed $(ARTIFACT_FORMAT)
	$(LL) ingest $(HUGE_SCENE) -o $(HUGE_OUT)/yarns.zarr $(LARGE_INGEST_ARGS)

$(HUGE_OUT)/tables.zarr/zarr.json: $(HUGE_OUT)/yarns.zarr/zarr.json $(wildcard stages/procedural/*.py)
	$(LL) tables $(HUGE_OUT)/yarns.zarr -o $(HUGE_OUT)/tables.zarr $(if $(HUGE_BUDGET),--budget $(HUGE_BUDGET))

$(HUGE_OUT)/close.exr: $(HUGE_OUT)/tables.zarr/zarr.json $(HUGE_SCENE)
	$(if $(HUGE_BUDGET),LOOMLIGHT_MEMORY_BUDGET=$(HUGE_BUDGET)) $(LL) render $(HUGE_SCENE) --method volpath \
	    --source procedural --tables $(HUGE_OUT)/tables.zarr $(HUGE_ARGS) -o $@

# make table1's room row and make room: the Sponza-class room (pipeline/room.py: eleven textiles, 42,752 yarns,
# ~900 GB if realized), written by `loomlight room`; bysdf renders it quickly, procedural volpath far more slowly
# (its time: docs/methods/volpath.md, "Limits"). ROOM_ROW= leaves the row out of make table1
ROOM_OUT ?= out/room
ROOM_ROW ?= 1
ROOM_SPP ?= 16
$(ROOM_OUT)/room.toml: pipeline/room.py $(VENV)/.installed
	$(LL) room -o $(ROOM_OUT)

$(ROOM_OUT)/yarns.zarr/zarr.json: $(ROOM_OUT)/room.toml $(ARTIFACT_FORMAT)
	$(LL) ingest $(ROOM_OUT)/room.toml -o $(ROOM_OUT)/yarns.zarr

$(ROOM_OUT)/tables.zarr/zarr.json: $(ROOM_OUT)/yarns.zarr/zarr.json $(wildcard stages/procedural/*.py)
	$(LL) tables $(ROOM_OUT)/yarns.zarr -o $(ROOM_OUT)/tables.zarr

$(ROOM_OUT)/bysdf.exr: $(ROOM_OUT)/yarns.zarr/zarr.json
	$(LL) render $(ROOM_OUT)/room.toml --method bysdf --set yarns=$(ROOM_OUT)/yarns.zarr --spp $(ROOM_SPP) -o $@

$(ROOM_OUT)/volpath.exr: $(ROOM_OUT)/tables.zarr/zarr.json
	$(LL) render $(ROOM_OUT)/room.toml --method volpath --source procedural --tables $(ROOM_OUT)/tables.zarr \
	    --spp $(ROOM_SPP) -o $@

room: $(ROOM_OUT)/bysdf.exr ## the Sponza-class room (11 textiles, 42,752 yarns, ~900 GB if realized) rendered by bysdf at 640x360, 16 spp -> out/room/bysdf.png

room-volpath: $(ROOM_OUT)/volpath.exr ## the room rendered by procedural volpath at 640x360, 16 spp (long: docs/methods/volpath.md, Limits) -> out/room/volpath.png

# HUGE_SCENE= leaves the 10x row out. The procedural and realized rows are make demo-full's evaluation renders
# (64x48 at 8 spp; made by a make of its settings)
TABLE1_EVAL = $(FULL_OUT)/eval/volpath-procedural.exr $(FULL_OUT)/eval/volpath-realized.exr
TABLE1_INPUTS = $(TABLE1_EVAL) $(LARGE_OUT)/close.exr $(if $(HUGE_SCENE),$(HUGE_OUT)/close.exr) \
    $(if $(ROOM_ROW),$(ROOM_OUT)/volpath.exr)
ifneq ($(OUT),$(FULL_OUT))
$(TABLE1_EVAL): FORCE
	@$(MAKE) --no-print-directory $(FULL_VARS) $@
endif
table1: $(TABLE1_INPUTS) ## Table 1 of Luan, Zhao, Bala 2017: data sizes, procedural vs realized volpath, the 1,000- and 3,200-yarn close-ups and the room (hours, about 20 GB) -> out/table1/report.md
	$(LL) evaluate --table1 --scene $(SCENE) --scene $(LARGE_SCENE) $(if $(HUGE_SCENE),--scene $(HUGE_SCENE)) \
	    $(if $(ROOM_ROW),--scene $(ROOM_OUT)/room.toml) \
	    --procedural $(FULL_OUT)/eval/volpath-procedural.exr --realized $(FULL_OUT)/eval/volpath-realized.exr \
	    --unrealized $(LARGE_OUT)/close.exr $(if $(HUGE_SCENE),--unrealized $(HUGE_OUT)/close.exr) \
	    $(if $(ROOM_ROW),--unrealized $(ROOM_OUT)/volpath.exr) -o out/table1
	@echo "report: out/table1/report.md"

# --- light sweeps and fiberpath against volpath ---
sweep: $(OUT)/fibers.zarr/zarr.json ## Khungurn et al. 2017 Fig. 13 / Table 2 style sweep of the demo over light directions and SG sharpness
	$(LL) evaluate --sweep data/sweeps/demo.toml -o $(OUT)/sweep
	@echo "report: $(OUT)/sweep/report.md"

$(AGREE)/twill/yarns.zarr/zarr.json: $(TWILL_SCENE) $(VENV)/.installed $(ARTIFACT_FORMAT)
	$(LL) ingest $(TWILL_SCENE) -o $(AGREE)/twill/yarns.zarr

$(AGREE)/twill/fibers.zarr/zarr.json: $(AGREE)/twill/yarns.zarr/zarr.json
	$(LL) realize $(AGREE)/twill/yarns.zarr -o $(AGREE)/twill/fibers.zarr

$(AGREE)/demo/%.exr: $(OUT)/fibers.zarr/zarr.json $(SCENE)
	$(LL) render $(SCENE) --method $(firstword $(subst -, ,$*)) --source realized --fibers $(OUT)/fibers.zarr $(AGREE_ARGS) -o $@

$(AGREE)/twill/%.exr: $(AGREE)/twill/fibers.zarr/zarr.json $(TWILL_SCENE)
	$(LL) render $(TWILL_SCENE) --method $(firstword $(subst -, ,$*)) --source realized --fibers $(AGREE)/twill/fibers.zarr $(AGREE_ARGS) -o $@

$(AGREE)/%/report/report.md: $(AGREE)/%/fiberpath.exr $(AGREE)/%/volpath.exr
	$(LL) evaluate --ref $(AGREE)/$*/fiberpath.exr --test $(AGREE)/$*/volpath.exr -o $(AGREE)/$*/report

.PRECIOUS: $(AGREE)/demo/%.exr $(AGREE)/twill/%.exr

AGREEMENT_INPUTS = $(AGREE)/demo/report/report.md $(AGREE)/twill/report/report.md $(AGREE)/twill/fibers.zarr/zarr.json sweep
agreement: $(AGREEMENT_INPUTS) ## fiberpath vs volpath on the demo and twill swatches, under the demo light and the sweep lights
	$(LL) evaluate --sweep data/sweeps/twill.toml -o $(AGREE)/twill/sweep
	@echo "reports: $(AGREE)/demo/report/report.md $(AGREE)/twill/report/report.md $(OUT)/sweep/report.md $(AGREE)/twill/sweep/report.md"

# --- Khungurn et al. 2017: precomputed light transport against path tracing, and its parameter studies ---
# make prt-sweep: the damask's two exemplars each alone on a flat patch (data/tilings/flat_satin41.toml,
# flat_satin14.toml; the exemplar only) and the draped damask, precomputed with PRT_SVF_ARGS / PRT_IIRTF_ARGS (the damask:
# PRT_DAMASK_IIRTF_ARGS); each swept over the demo sweep's 12 lights, prt against
# fiberpath at 16 spp (data/sweeps/prt_*.toml), then split into single and multiple scattering
# (loomlight study prt-terms). make prt-study: Khungurn et al. 2017 §6.1's cell-size and SH-order strips on one cheap
# exemplar (data/studies/prt_params.toml). The sweep files name these paths (out/prt).
PRT_SWEEPS := flat41 flat14 damask
PRT_SVF_ARGS ?= --resolution 128 --components 48
PRT_IIRTF_ARGS ?= --order 4 --cell-factor 1.5 --paths 200 --light-sampling mis
# the draped damask also holds light from below (its hanging sides under the low light; docs/methods/prt.md)
PRT_DAMASK_IIRTF_ARGS ?= $(PRT_IIRTF_ARGS) --light-domain sphere
PRT_EXEMPLAR_41 := 0
PRT_EXEMPLAR_14 := 1

$(PRT)/flat%_tiling.zarr/zarr.json: data/tilings/flat_satin%.toml data/scenes/flat_satin.toml $(VENV)/.installed $(ARTIFACT_FORMAT)
	$(LL) tile data/tilings/flat_satin$*.toml -o $(PRT)/flat$*_tiling.zarr

$(PRT)/flat%_svf.zarr/zarr.json: $(PRT)/flat%_tiling.zarr/zarr.json $(wildcard stages/precompute/*.py stages/precompute/*/*.py)
	$(LL) precompute svf $(PRT)/flat$*_tiling.zarr -o $(PRT)/flat$*_svf.zarr --exemplar $(PRT_EXEMPLAR_$*) $(PRT_SVF_ARGS)

$(PRT)/flat%_iirtf.zarr/zarr.json: $(PRT)/flat%_tiling.zarr/zarr.json data/scenes/flat_satin.toml $(wildcard stages/precompute/*.py stages/precompute/*/*.py) pipeline/limits.py pipeline/runners/precompute.py
	$(LL) precompute iirtf $(PRT)/flat$*_tiling.zarr -o $(PRT)/flat$*_iirtf.zarr --exemplar $(PRT_EXEMPLAR_$*) $(PRT_IIRTF_ARGS)

$(PRT)/damask_tiling.zarr/zarr.json: $(TILING) data/tilings/damask_motif.png $(DAMASK_SCENE) $(VENV)/.installed $(ARTIFACT_FORMAT)
	$(LL) tile $(TILING) -o $(PRT)/damask_tiling.zarr

$(PRT)/damask_svf.zarr/zarr.json: $(PRT)/damask_tiling.zarr/zarr.json $(wildcard stages/precompute/*.py stages/precompute/*/*.py)
	$(LL) precompute svf $(PRT)/damask_tiling.zarr -o $(PRT)/damask_svf.zarr $(PRT_SVF_ARGS)

$(PRT)/damask_iirtf.zarr/zarr.json: $(PRT)/damask_tiling.zarr/zarr.json $(DAMASK_SCENE) $(wildcard stages/precompute/*.py stages/precompute/*/*.py) pipeline/limits.py pipeline/runners/precompute.py
	$(LL) precompute iirtf $(PRT)/damask_tiling.zarr -o $(PRT)/damask_iirtf.zarr $(PRT_DAMASK_IIRTF_ARGS)

.PRECIOUS: $(PRT)/damask_%.zarr/zarr.json $(PRT)/flat%_tiling.zarr/zarr.json $(PRT)/flat%_svf.zarr/zarr.json $(PRT)/flat%_iirtf.zarr/zarr.json

PRT_SWEEP_INPUTS = $(foreach s,41 14,$(PRT)/flat$(s)_svf.zarr/zarr.json $(PRT)/flat$(s)_iirtf.zarr/zarr.json) \
	$(PRT)/damask_svf.zarr/zarr.json $(PRT)/damask_iirtf.zarr/zarr.json
prt-sweep: $(PRT_SWEEP_INPUTS) ## Khungurn et al. 2017: prt against fiberpath on the damask's flat satins and the draped damask, 12 lights, split into terms (out/prt)
	@for s in $(PRT_SWEEPS); do \
	    $(LL) evaluate --sweep data/sweeps/prt_$$s.toml -o $(PRT)/$$s && \
	    $(LL) study prt-terms data/sweeps/prt_$$s.toml --sweep-dir $(PRT)/$$s -o $(PRT)/$$s-terms || exit 1; \
	done
	@for s in $(PRT_SWEEPS); do echo "reports: $(PRT)/$$s/report.md $(PRT)/$$s-terms/attribution.md"; done

prt-study: $(VENV)/.installed ## Khungurn et al. 2017 §6.1: the cell-size and SH-order strips on one exemplar (out/prt/study)
	$(LL) study prt-params data/studies/prt_params.toml -o $(PRT)/study
	@echo "report: $(PRT)/study/report.md (strips $(PRT)/study/cell_size.png, $(PRT)/study/sh_order.png)"

# --- Daubert et al. 2001 ---
# make btf-sweep: Daubert et al. 2001 fitted texture of each damask exemplar alone on its flat patch (the prt sweep's
# tilings, out/prt/flat41_tiling.zarr and flat14), fitted at the defaults of precompute btf (BTF_SWEEP_ARGS) with
# both models (the Lafortune fit and the compressed table: --model tabulated)
# into out/btf/, and of the knit swatch's stitch (make compare's, out/compare/inputs/knit_btf.zarr), against
# fiberpath under the demo sweep's 12 lights (data/sweeps/btf_*.toml); beside them the table acquired on
# half-vector light cells (--light-coords half: out/btf/*_btf_half.zarr)
BTF_SWEEP_ARGS ?=
BTF_HALF_DEPS := $(wildcard stages/precompute/*.py stages/precompute/*/*.py) stages/core/btf.py pipeline/limits.py pipeline/runners/precompute_btf.py

$(BTF_DIR)/flat%_btf.zarr/zarr.json: $(PRT)/flat%_tiling.zarr/zarr.json data/scenes/flat_satin.toml $(wildcard stages/precompute/*.py stages/precompute/*/*.py) pipeline/limits.py pipeline/runners/precompute_btf.py
	$(LL) precompute btf $(PRT)/flat$*_tiling.zarr -o $(BTF_DIR)/flat$*_btf.zarr --exemplar $(PRT_EXEMPLAR_$*) --model tabulated $(BTF_SWEEP_ARGS)

$(BTF_DIR)/flat%_btf_half.zarr/zarr.json: $(PRT)/flat%_tiling.zarr/zarr.json data/scenes/flat_satin.toml $(BTF_HALF_DEPS)
	$(LL) precompute btf $(PRT)/flat$*_tiling.zarr -o $(BTF_DIR)/flat$*_btf_half.zarr --exemplar $(PRT_EXEMPLAR_$*) --model tabulated --light-coords half $(BTF_SWEEP_ARGS)

$(BTF_DIR)/knit_btf_half.zarr/zarr.json: $(COMPARE_IN)/knit_tiling.zarr/zarr.json $(BTF_HALF_DEPS)
	$(LL) precompute btf $(COMPARE_IN)/knit_tiling.zarr -o $(BTF_DIR)/knit_btf_half.zarr --model tabulated --light-coords half $(BTF_SWEEP_ARGS)

.PRECIOUS: $(BTF_DIR)/flat%_btf.zarr/zarr.json $(BTF_DIR)/flat%_btf_half.zarr/zarr.json $(BTF_DIR)/knit_btf_half.zarr/zarr.json

btf-sweep: $(foreach s,41 14,$(BTF_DIR)/flat$(s)_btf.zarr/zarr.json $(BTF_DIR)/flat$(s)_btf_half.zarr/zarr.json) $(COMPARE_IN)/knit_btf.zarr/zarr.json $(BTF_DIR)/knit_btf_half.zarr/zarr.json ## Daubert et al. 2001: fitted textures of the damask's two satins and a knit against fiberpath, 12 lights, hemisphere and half-vector light cells (out/btf)
	@for s in flat41 flat14 knit; do $(LL) evaluate --sweep data/sweeps/btf_$$s.toml -o $(BTF_DIR)/$$s || exit 1; done
	@for s in flat41 flat14 knit; do echo "report: $(BTF_DIR)/$$s/report.md"; done

btf-through: ## after make compare: the knit tiling's tabulated btf, lit from above on the top face and lit from below too with a plane per texel (relief), beside the fibres (docs/img/btf_knit_through.png)
	$(BIN)/python scripts/btf_planes.py $(COMPARE)/knit_btf -o $(BTF_DIR) --method btf_tabulated "hemisphere, top face" \
	    --method btf_through "sphere, relief" --docs

btf-azimuth: $(PRT)/flat14_tiling.zarr/zarr.json ## what a btf light grid misses: the flat 1/4 satin's mean against the light's azimuth, fiberpath, the 8x8 table and the 15x15 half-vector cells (out/btf/azimuth, docs/img/btf_light_azimuth.png)
	$(BIN)/python scripts/btf_light_azimuth.py -o $(BTF_DIR)/azimuth --docs

# --- yarn colours (pipeline/dye.py) ---
albedo-curves: $(VENV)/.installed ## measure the albedo curve of every bundled BCSDF on every bundled yarn, and bysdf's colour curve of every yarn -> data/bcsdf/albedo_curves.json
	$(BIN)/python scripts/albedo_curves.py

gallery: $(VENV)/.installed ## the material chart: every BCSDF preset x four yarn colours, studio-lit, and the colour check under a white sky: the converged fibres, bysdf and volpath (out/gallery, docs/img/material_chart.png)
	$(BIN)/python scripts/colour_chart.py -o out/gallery --spp 64 --sky-spp 128 --methods bysdf,volpath --docs
