# The two set-up commands. Each installs missing Debian packages, configures and builds first.
#   make demo   run the main job on the embedded default case and list what it wrote
#   make test   build and run the whole test suite through CTest
BUILD_DIR ?= build
JOBS ?= $(shell nproc)
CMAKE_ARGS ?=
# ccache keys on paths relative to the checkout, so a fresh clone elsewhere reuses the cache.
export CCACHE_BASEDIR ?= $(CURDIR)

.PHONY: all deps configure build demo test sanitize bench clean

all: build

deps:
	@scripts/install-deps

# CMake runs when the build directory is new or CMAKE_ARGS changed; otherwise Ninja re-runs it
# itself whenever a CMakeLists.txt changes (this saves `make demo` a second and a half).
configure: deps
	@if [ ! -f $(BUILD_DIR)/build.ninja ] || [ "$$(cat $(BUILD_DIR)/.make-cmake-args 2>/dev/null)" != "$(CMAKE_ARGS)" ]; then \
	  cmake -S . -B $(BUILD_DIR) -G Ninja -DCMAKE_BUILD_TYPE=Release $(CMAKE_ARGS) > $(BUILD_DIR).configure.log 2>&1 \
	    || { cat $(BUILD_DIR).configure.log; exit 1; }; \
	  printf '%s' "$(CMAKE_ARGS)" > $(BUILD_DIR)/.make-cmake-args; \
	fi

build: configure
	@cmake --build $(BUILD_DIR) -j $(JOBS)

demo: build
	@$(BUILD_DIR)/pipeline/organsmith run --out out

test: build
	@cd $(BUILD_DIR) && ctest --output-on-failure -j $(JOBS)

# The sanitizer job: ASan + UBSan (asserts on, -O1) build in build-asan/ of the CLI and the tests
# of everything that reads untrusted input — ingest of every format, case files, TOML, CSV,
# segmentation, label-map checks before meshing, and the corpus suite, whose 418 hostile inputs
# go through the instrumented CLI; and the meshing tests that reach CGAL's preconditions (asserts
# are on in this build: flat cuts, the tube-wall join, the label touching the border; of the
# phantom's six, the trachea's: each meshes the phantom, ≈ 50 s under ASan). CGAL's own code is left uninstrumented (meshing/CMakeLists.txt).
# With -g, ccache would key each object on the checkout's path: CCACHE_NOHASHDIR lets a fresh
# clone reuse what another one compiled (reports print the relative source paths either way).
SAN_DIR ?= build-asan
SAN_TARGETS = organsmith test_core test_pipeline test_corpus test_physics test_segmentation test_meshing
# Left out: BadInputs.InterruptAndKillMidRunThenRerun (its full run draws snapshots through Mesa
# under Xvfb; the driver, unloaded at exit, leaves 112 bytes that LeakSanitizer cannot attribute).
# Also left out: SegmentSweep.RealGallbladderLikeUnseenScansMoreNoiseDraws (305 s here; the same
# code paths as RealGallbladderLikeUnseenScans, which stays in, on 63 more noise draws).
SAN_EXCLUDE ?= ^SegmentSweep\.RealGallbladderLikeUnseenScansMoreNoiseDraws$$
SAN_TESTS ?= ^(ImageGrid|LabelMap|Sha256|Csv|TomlParse|PhysicsCsv|Ingest|IngestReal|IngestErrors|CaseFile|OutputDir|NiftiCheck|DicomStructure|TextHeaders|BadInputs\.(CaseFile|MeshOptions|ADevice)|Corpus|Gvf|Snake|SegmentPhantom|SegmentBadInput|SegmentReal|SegmentSweep|MeshingDeterminism|MeshingBadInput|TubeWall)\.|^PhantomMeshes\.TracheaIsATube
sanitize: deps
	@cmake -S . -B $(SAN_DIR) -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g" \
	  -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g" -DORGANSMITH_SANITIZE=ON > $(SAN_DIR).configure.log 2>&1 \
	  || { cat $(SAN_DIR).configure.log; exit 1; }
	@CCACHE_NOHASHDIR=1 cmake --build $(SAN_DIR) -j $(JOBS) --target $(SAN_TARGETS)
	@cd $(SAN_DIR) && ASAN_OPTIONS=detect_leaks=1:abort_on_error=0:exitcode=97 \
	  LSAN_OPTIONS=suppressions=$(CURDIR)/tests/sanitizer/lsan.supp:exitcode=98 \
	  UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1:exitcode=96 \
	  ctest --output-on-failure -j $(JOBS) -R '$(SAN_TESTS)' -E '$(SAN_EXCLUDE)'

# Every benchmark in turn (each prints its figures and ratios; a failed target does not stop the rest).
BENCHES = bench_ingest segmentation/bench_gvf segmentation/bench_segment meshing/bench_meshing \
          physics/bench_physics physics/bench_haptics physics/bench_degradation viewer/bench_viewer
bench: build
	@for b in $(BENCHES); do echo "== $$b"; $(BUILD_DIR)/bench/$$b || echo "($$b: target not met)"; done
	@echo "== cohort engines"; bash bench/pipeline/cohort_bench.sh $(BUILD_DIR) || echo "(cohort bench failed)"
	@echo "== PACS pulls"; bash bench/pipeline/pull_bench.sh $(BUILD_DIR) || echo "(pull bench failed)"
	@echo "== solver exports and runs"; bash bench/pipeline/solver_bench.sh $(BUILD_DIR) || echo "(solver bench failed)"
	@echo "== real-time tissue model"; bash bench/physics/realtime_tissue.sh $(BUILD_DIR) || echo "(real-time tissue bench failed)"

clean:
	@rm -rf $(BUILD_DIR) $(BUILD_DIR).configure.log
