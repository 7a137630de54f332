# The two set-up commands. Each installs missing Debian packages, configures and builds first.
#   make demo   run the main job on the embedded default case and list what it wrote
#   make test   build and run the whole test suite through CTest
BUILD_DIR ?= build
JOBS ?= $(shell nproc)
CMAKE_ARGS ?=
# ccache keys on paths relative to the checkout, so a fresh clone elsewhere reuses the cache.
export CCACHE_BASEDIR ?= $(CURDIR)

.PHONY: all deps configure build demo test bench clean

all: build

deps:
	@scripts/install-deps

configure: deps
	@cmake -S . -B $(BUILD_DIR) -G Ninja -DCMAKE_BUILD_TYPE=Release $(CMAKE_ARGS) > $(BUILD_DIR).configure.log 2>&1 \
	  || { cat $(BUILD_DIR).configure.log; exit 1; }

build: configure
	@cmake --build $(BUILD_DIR) -j $(JOBS)

demo: build
	@$(BUILD_DIR)/pipeline/organsmith run --out out

test: build
	@cd $(BUILD_DIR) && ctest --output-on-failure -j $(JOBS)

# Every benchmark in turn (each prints its figures and ratios; a failed target does not stop the rest).
BENCHES = bench_ingest segmentation/bench_gvf segmentation/bench_segment meshing/bench_meshing \
          physics/bench_physics physics/bench_haptics physics/bench_degradation viewer/bench_viewer
bench: build
	@for b in $(BENCHES); do echo "== $$b"; $(BUILD_DIR)/bench/$$b || echo "($$b: target not met)"; done
	@echo "== cohort engines"; bash bench/pipeline/cohort_bench.sh $(BUILD_DIR) || echo "(cohort bench failed)"
	@echo "== PACS pulls"; bash bench/pipeline/pull_bench.sh $(BUILD_DIR) || echo "(pull bench failed)"
	@echo "== solver exports and runs"; bash bench/pipeline/solver_bench.sh $(BUILD_DIR) || echo "(solver bench failed)"

clean:
	@rm -rf $(BUILD_DIR) $(BUILD_DIR).configure.log
