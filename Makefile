# Two commands do all the set-up on a fresh machine:
#   make demo   builds the FMUs and runs the main job
#   make test   builds the FMUs and runs every test (Rust and Python/fmpy)
# They install what they need: libclang (Debian package, for fmi-sys's bindgen)
# when it is missing, and a .venv with the pinned Python packages of
# tests/requirements.txt. Rust crates come from Cargo.lock. The FMUs'
# linux64 (glibc 2.17) and win64 binaries need zig and mingw-w64, which
# packaging/platform-binaries.sh installs (build/tools, apt-get); the win64
# tests need wine (apt-get).

SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
CARGO ?= cargo
PYTHON3 ?= python3
VENV := .venv
PY := $(VENV)/bin/python
DIST := dist
BUILD := build
RELEASE := target/release

# identifier:cargo-package:describe-binary
PLANT := FlexureStage:fmu-plant:flexure-stage-describe
CONTROLLER := PiezoController:fmu-controller:piezo-controller-describe
FMU_SPECS := $(PLANT) $(CONTROLLER)
# The FMUs' platform binaries, built by packaging/platform-binaries.sh:
# binaries/<platform>/<library> for linux64 (glibc 2.17) and win64.
PLATFORM_BINARIES := $(BUILD)/binaries

.PHONY: all fmus test demo lint master sweep rust-test python-test model-descriptions stage-preset stage-memory-preset stage-no-memory-preset xy200s-preset xy200s-controller-preset identify system-deps wine venv clean

all: fmus

# fmi-sys generates its FMI 2.0 bindings with bindgen, which needs libclang.
system-deps:
	@# rustc links through the C compiler, which the C importer tests use too.
	@if ! command -v cc >/dev/null; then \
	  packaging/apt-install.sh "rustc links with it, the C importer tests compile with it" \
	    gcc libc6-dev || exit 1; \
	fi
	@if ! ldconfig -p | grep -q 'libclang[-0-9.]*\.so'; then \
	  packaging/apt-install.sh "bindgen needs libclang" libclang-dev || exit 1; \
	fi
	@# fmi2-conformance's memory test runs FMU lifetimes under valgrind.
	@if ! command -v valgrind >/dev/null; then \
	  packaging/apt-install.sh "the memory test of the FMUs runs under it" valgrind \
	    || echo "without valgrind the memory test will fail" >&2; \
	fi

# tests/test_windows_binaries.py runs the win64 binaries under wine. Not fatal
# here: without wine that test fails and says why.
wine:
	@if ! command -v wine64 >/dev/null && [ ! -x /usr/lib/wine/wine64 ] && ! command -v wine >/dev/null; then \
	  packaging/apt-install.sh "runs the win64 binaries in the tests" wine64 \
	    || echo "without wine tests/test_windows_binaries.py will fail" >&2; \
	fi

$(VENV)/.installed: tests/requirements.txt
	@# Debian's python3 leaves ensurepip, which venv needs, to python3-venv.
	@if ! $(PYTHON3) -c 'import ensurepip' 2>/dev/null; then \
	  packaging/apt-install.sh "python3 -m venv needs ensurepip" python3-venv || exit 1; \
	fi
	$(PYTHON3) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r tests/requirements.txt
	touch $@

venv: $(VENV)/.installed

# Builds the host binaries (describe and preset tools, the packer, the
# libraries `cargo test` loads), the platform binaries (linux64 against glibc
# 2.17, win64), writes each FMU's description from its variable table and
# packs dist/<identifier>.fmu with every platform binary that could be built;
# a platform whose toolchain is missing is reported loudly, here and again
# at the end.
fmus: system-deps
	$(CARGO) build --release --locked $(or $(BUILD_SCOPE),-p fmu-plant -p fmu-controller -p packaging)
	CARGO=$(CARGO) PYTHON3=$(PYTHON3) packaging/platform-binaries.sh $(PLATFORM_BINARIES) \
	  $(foreach spec,$(FMU_SPECS),$(word 2,$(subst :, ,$(spec))))
	@for spec in $(FMU_SPECS); do \
	  IFS=: read -r id pkg describe <<< "$$spec"; \
	  crate=$${pkg//-/_}; \
	  binaries=(); \
	  for platform_file in linux64=lib$$crate.so win64=$$crate.dll; do \
	    platform=$${platform_file%%=*}; \
	    file=$(PLATFORM_BINARIES)/$$platform/$${platform_file#*=}; \
	    if [ -f "$$file" ]; then binaries+=(--binary "$$platform=$$file"); fi; \
	  done; \
	  rm -rf $(BUILD)/$$id; \
	  $(RELEASE)/$$describe $(BUILD)/$$id; \
	  $(RELEASE)/fmu-pack --description $(BUILD)/$$id "$${binaries[@]}" --out $(DIST)/$$id.fmu; \
	done
	@# Parameter sets by FMI name, to load a preset into an FMU before
	@# initialization (fmpy start_values, a Simulink mask, an SSP .ssv).
	mkdir -p $(DIST)/presets
	$(RELEASE)/flexure-stage-parameters 3dof $(DIST)/presets/FlexureStage.3dof.json
	$(RELEASE)/flexure-stage-parameters 3dof_memory $(DIST)/presets/FlexureStage.3dof_memory.json
	$(RELEASE)/flexure-stage-parameters 3dof_no_memory $(DIST)/presets/FlexureStage.3dof_no_memory.json
	$(RELEASE)/flexure-stage-parameters xy200s $(DIST)/presets/FlexureStage.xy200s.json
	$(RELEASE)/piezo-controller-parameters stage $(DIST)/presets/PiezoController.stage.json
	$(RELEASE)/piezo-controller-parameters piezo-models/presets/piezo_controller_stage_once.json \
	  $(DIST)/presets/PiezoController.stage_once.json
	$(RELEASE)/piezo-controller-parameters piezo-models/presets/piezo_controller_stage_memory.json \
	  $(DIST)/presets/PiezoController.stage_memory.json
	$(RELEASE)/piezo-controller-parameters piezo-models/presets/piezo_controller_stage_memory_once.json \
	  $(DIST)/presets/PiezoController.stage_memory_once.json
	$(RELEASE)/piezo-controller-parameters piezo-models/presets/piezo_controller_stage_no_memory.json \
	  $(DIST)/presets/PiezoController.stage_no_memory.json
	$(RELEASE)/piezo-controller-parameters piezo-models/presets/piezo_controller_stage_no_memory_once.json \
	  $(DIST)/presets/PiezoController.stage_no_memory_once.json
	$(RELEASE)/piezo-controller-parameters paper $(DIST)/presets/PiezoController.paper.json
	$(RELEASE)/piezo-controller-parameters piezo-models/presets/piezo_controller_xy200s.json \
	  $(DIST)/presets/PiezoController.xy200s.json
	@if [ -s $(PLATFORM_BINARIES)/WARNINGS ]; then cat $(PLATFORM_BINARIES)/WARNINGS >&2; fi

# Rewrites the committed modelDescription/*.xml after an interface change
# (a test fails while they differ from a fresh generation).
model-descriptions: system-deps
	$(CARGO) build --release --locked -p fmu-plant -p fmu-controller
	@for spec in $(FMU_SPECS); do \
	  IFS=: read -r id pkg describe <<< "$$spec"; \
	  $(RELEASE)/$$describe $(BUILD)/describe-$$id; \
	  cp $(BUILD)/describe-$$id/modelDescription.xml modelDescription/$$id.xml; \
	  echo "modelDescription/$$id.xml"; \
	done

lint: system-deps
	$(CARGO) fmt --all --check
	$(CARGO) clippy --workspace --all-targets --locked -- -D warnings

# The ABI tests load the cdylibs, which `cargo test` does not rebuild.
rust-test: system-deps
	$(CARGO) build --workspace --release --locked
	$(CARGO) test --workspace --release --locked

# The closed loop packaged for other tools, generated from the FMUs'
# descriptions, dist/presets and demo/cosim.py's wiring: an SSP 1.0 package
# (OMSimulator, libcosim, fmpy.ssp) and the loop as one container FMU.
.PHONY: systems
systems: fmus venv
	$(PY) -m demo.systems --dist $(DIST)

python-test: fmus venv systems wine master fingerprints-tool
	$(PY) -m pytest tests -q -rP

# Under `make test` the builds of fmus, master and fingerprints-tool take the
# whole workspace, as rust-test's does: cargo unifies dependency features over
# the packages it builds, so a package subset gets other features (rand's,
# nalgebra's) and compiles piezo-models and what depends on it again, three
# times over; with the same scope they are already built. Alone, each builds
# only its packages.
test: BUILD_SCOPE = --workspace
test: lint rust-test python-test

# The main job: seed 000's experiments in closed loop (CSV, PNG, report.md in
# out/demo), then the plant's fingerprints beside the paper (out/plant).
demo: fmus venv systems fingerprints-tool
	$(PY) -m demo --out out/demo
	$(RELEASE)/plant-fingerprints --fmu $(DIST)/FlexureStage.fmu --out out/plant
	@echo "report: out/demo/report.md (plant: out/plant/report.md)"

# Re-identifies the controller on the plant (seed 000 §3.1 and §4) and bakes
# the result into PiezoController's start values; writes beside it the same
# preset with D1..D4 fitted once (seed 000 §4's procedure, which make demo's
# seed 000 table runs; the start values refine them over three rounds). Run
# after a plant change.
stage-preset: fmus
	$(CARGO) build --release --locked -p piezo-identify
	mkdir -p out/stage
	$(RELEASE)/piezo-identify stage --plant $(DIST)/FlexureStage.fmu \
	  --out piezo-models/presets/piezo_controller_stage.json \
	  --out-fitted-once piezo-models/presets/piezo_controller_stage_once.json \
	  --report out/stage/identification.json
	$(MAKE) model-descriptions fmus

# PiezoController identified by the same procedure on seed 000's stage with
# its stacks' return-point memory on, calibrated with it (the 3dof_memory
# parameter set; docs/seed000.md measures both beside each other).
stage-memory-preset: fmus
	$(CARGO) build --release --locked -p piezo-identify
	mkdir -p out/stage
	$(RELEASE)/piezo-identify stage --plant $(DIST)/FlexureStage.fmu \
	  --plant-parameters $(DIST)/presets/FlexureStage.3dof_memory.json \
	  --out piezo-models/presets/piezo_controller_stage_memory.json \
	  --out-fitted-once piezo-models/presets/piezo_controller_stage_memory_once.json \
	  --report out/stage/memory_identification.json
	$(MAKE) fmus

# PiezoController identified by the same procedure on seed 000's stage as
# the project shipped it until the stacks' minor loops were closed: seed
# 001's eq. (3) as integrated, no return-point memory, the modes calibrated
# to the Ziegler-Nichols figures of a held point (the 3dof_no_memory
# parameter set; docs/seed000.md measures it beside the default).
stage-no-memory-preset: fmus
	$(CARGO) build --release --locked -p piezo-identify
	mkdir -p out/stage
	$(RELEASE)/piezo-identify stage --plant $(DIST)/FlexureStage.fmu \
	  --plant-parameters $(DIST)/presets/FlexureStage.3dof_no_memory.json \
	  --out piezo-models/presets/piezo_controller_stage_no_memory.json \
	  --out-fitted-once piezo-models/presets/piezo_controller_stage_no_memory_once.json \
	  --report out/stage/no_memory_identification.json
	$(MAKE) fmus

# PiezoController identified on the XY200S preset of FlexureStage by the same
# procedure as the stage preset, rescaled to its strokes (144.37 / 12.74 =
# 11.33: 113 um sines, cutoffs at +-113 um), with the PI gains scaled by the
# inverse of the XY200S's um per volt relative to seed 000's stage (0.085),
# its 0..10 V command range (0..150 V, seed 001 §5.2) and therefore the held
# axis at half stroke (72, 75 um), the home seed 000 §3.2 gives an axis whose
# actuators cannot go below 0 V. It does not rotate (one x actuator).
xy200s-controller-preset: fmus
	$(CARGO) build --release --locked -p piezo-identify
	mkdir -p out/stage
	$(RELEASE)/piezo-identify stage --plant $(DIST)/FlexureStage.fmu \
	  --plant-parameters $(DIST)/presets/FlexureStage.xy200s.json --scale 11.3320 --no-rotation \
	  --held 72.19,74.64 --command-range 0,10 --gain-scale 0.085 \
	  --out piezo-models/presets/piezo_controller_xy200s.json \
	  --report out/stage/xy200s_identification.json
	$(MAKE) fmus

# Seed 001's XY200S stage as a FlexureStage parameter set, converted from the
# printed Tables 1-2 (piezo-identify/src/xy200s.rs says how); a test fails
# when the committed preset and a fresh conversion differ.
xy200s-preset: system-deps
	$(CARGO) build --release --locked -p piezo-identify
	mkdir -p out/xy200s
	$(RELEASE)/piezo-identify xy200s-preset --out piezo-models/presets/xy200s_stage.json \
	  --report out/xy200s/conversion.json

# The identification figures: seed 000's model comparison on the plant (F of
# eq. 7, evaluation time), then the default identification of every real
# record (P-885, split in two and fitted/validated) and of the lab-like
# records from FlexureStage by seed 000's modified inverse P-I and seed 001's
# Bouc-Wen, seeds 0-2, beside their baselines (docs/identification.md).
identify: system-deps
	$(CARGO) build --release --locked -p piezo-identify
	mkdir -p out/identify
	$(RELEASE)/piezo-identify compare --synthetic | tee out/identify/compare.txt
	piezo-identify/benches/figures.sh $(RELEASE)/piezo-identify | tee out/identify/figures.md

# The identification CLI alone, target/release/piezo-identify (README:
# fitting the models to your stage's data), with what its build needs.
.PHONY: identify-tool
identify-tool: system-deps
	$(CARGO) build --release --locked -p piezo-identify --bin piezo-identify

# The plant's calibration fingerprints measured through its FMU (procedures
# and targets: piezo-models/src/fingerprint.rs); make demo and
# tests/test_plant_fingerprints.py run it.
.PHONY: fingerprints-tool
fingerprints-tool: system-deps
	$(CARGO) build --release --locked $(or $(BUILD_SCOPE),-p piezo-identify --bin plant-fingerprints)

# The co-simulation master (piezo-cosim/), shipped inside the Python package
# as demo/bin/piezo-cosim: `python -m demo.master` and the sweeps' dask
# workers run it from there.
master: system-deps
	$(CARGO) build --release --locked $(or $(BUILD_SCOPE),-p piezo-cosim)
	install -D -m 755 $(RELEASE)/piezo-cosim demo/bin/piezo-cosim

# The default studies (demo/sweeps/*.toml) on a LocalCluster of this
# machine's cores: one Parquet table per study, heatmaps and report.md in
# out/sweep. Runs already in a table are skipped (an interrupted sweep
# continues); SWEEP_ARGS passes options (--scheduler tcp://HOST:PORT,
# --workers N, --restart).
SWEEP_ARGS ?=
sweep: fmus venv master
	$(PY) -m demo.sweep demo/sweeps/envelope.toml demo/sweeps/robustness.toml --out out/sweep $(SWEEP_ARGS)

clean:
	rm -rf $(BUILD) $(DIST) out demo/bin
