# Two commands do everything on a fresh Debian 12 machine:
#   make demo   install what is missing, build, run the main job on the project's default model
#   make test   install what is missing, build, run the whole test suite
# CI (.ci/run) adds:
#   make check-sanitize-ci  clang ASan + UBSan: the sanitized subset of the unit tests, then every reader's
#                           libFuzzer target for 20 s from the corpus and the kept findings
# By hand (docs/dev.md, "Sanitizers and fuzzing"):
#   make check-sanitize  the unit tests built with ASan + UBSan in build-asan/ (gcc), failing on any report
#   make fuzz            every reader's libFuzzer target (clang) for FUZZ_SECONDS each, failing on any finding
BUILD ?= build
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?=
LIDEF = $(BUILD)/app/lidef
DEMO_OUT ?= out/demo

.PHONY: all deps configure build demo test bench clean format check-sanitize check-sanitize-ci fuzz

all: build

deps:
	@bash scripts/install-deps.sh

configure: deps
	@cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release $(CMAKE_FLAGS) > /dev/null

build: configure
	@cmake --build $(BUILD) -j $(JOBS)

demo: build
	@bash scripts/demo.sh $(LIDEF) $(DEMO_OUT)

test: build
	@cd $(BUILD) && ctest --output-on-failure -j $(JOBS) --timeout 1500

# ASan + UBSan build of the unit tests (docs/dev.md, "Sanitizers and fuzzing"). Its own build folder and flags, so the
# normal build keeps its objects; ccache keeps both (base_dir makes worktrees share entries). -O1: ASan's usual
# level; -g1: line tables, enough for symbolized reports and cheaper to compile than -g. Eigen's bounds
# assertions stay on (no NDEBUG). The studio and the benchmarks are not built: the
# studio's own tests need the X server and VTK's OpenGL stack under ASan; nothing in them is a reader.
ASAN_BUILD ?= build-asan
SANITIZE_FLAGS = -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer
check-sanitize: deps
	@cmake -S . -B $(ASAN_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Sanitize \
	  -DCMAKE_CXX_FLAGS_SANITIZE="-O1 -g1 $(SANITIZE_FLAGS)" -DCMAKE_C_FLAGS_SANITIZE="-O1 -g1 $(SANITIZE_FLAGS)" \
	  -DCMAKE_EXE_LINKER_FLAGS_SANITIZE="$(SANITIZE_FLAGS)" -DCMAKE_SHARED_LINKER_FLAGS_SANITIZE="$(SANITIZE_FLAGS)" \
	  -DLIDEF_BUILD_STUDIO=OFF -DLIDEF_BUILD_BENCH=OFF $(CMAKE_FLAGS) > /dev/null
	@cmake --build $(ASAN_BUILD) -j $(JOBS)
	@bash scripts/check-sanitize.sh $(ASAN_BUILD) $(JOBS)

# What CI runs (.ci/run): one clang build with ASan + UBSan (and libFuzzer's coverage) of the libraries, compiled
# once for both of its parts:
#   1. the sanitized subset of the unit tests (tests/CMakeLists.txt, LIDEF_SANITIZE_TEST_SOURCES: the core's and
#      the analysis library's tests that do not start the CLI), label "sanitize", failing on any report;
#   2. every reader's libFuzzer target for CI_FUZZ_SECONDS each from the committed corpus and every kept finding
#      (a kept finding that comes back fails at once), seed 1; a new finding fails CI with its input in the log.
# -O1 and line tables: ASan's usual level, cheap to compile. docs/dev.md, "Sanitizers and fuzzing".
ASAN_CI_BUILD ?= build-sanitize-ci
CI_FUZZ_SECONDS ?= 20
check-sanitize-ci: deps
	@cmake -S . -B $(ASAN_CI_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Sanitize -DCMAKE_C_COMPILER=clang \
	  -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_CXX_FLAGS_SANITIZE="-O1" -DCMAKE_C_FLAGS_SANITIZE="-O1" \
	  -DLIDEF_FUZZ=ON -DLIDEF_BUILD_STUDIO=OFF -DLIDEF_BUILD_BENCH=OFF $(CMAKE_FLAGS) > /dev/null
	@cmake --build $(ASAN_CI_BUILD) -j $(JOBS) --target lidef_sanitize_tests fuzzers
	@SANITIZE_LABEL='^sanitize$$' bash scripts/check-sanitize.sh $(ASAN_CI_BUILD) $(JOBS)
	@FUZZ_SEED=1 bash scripts/fuzz.sh $(ASAN_CI_BUILD) $(CI_FUZZ_SECONDS) $(JOBS)

# libFuzzer targets of fuzz/ (clang, ASan + UBSan), each run FUZZ_SECONDS, JOBS at a time; only the libraries
# the readers need are built (target `fuzzers`). Findings: build-fuzz/fuzz-artifacts/ (fuzz/README.md).
FUZZ_BUILD ?= build-fuzz
FUZZ_SECONDS ?= 60
fuzz: deps
	@cmake -S . -B $(FUZZ_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_C_COMPILER=clang \
	  -DCMAKE_CXX_COMPILER=clang++ -DLIDEF_FUZZ=ON -DLIDEF_BUILD_TESTS=OFF -DLIDEF_BUILD_STUDIO=OFF \
	  -DLIDEF_BUILD_BENCH=OFF $(CMAKE_FLAGS) > /dev/null
	@cmake --build $(FUZZ_BUILD) -j $(JOBS) --target fuzzers
	@bash scripts/fuzz.sh $(FUZZ_BUILD) $(FUZZ_SECONDS) $(JOBS)

bench: build
	@bash scripts/bench.sh $(BUILD)

format:
	@find deform analysis app opencl gui tests bench python/src examples/cpp -name '*.cpp' -o -name '*.h' | xargs clang-format -i

clean:
	rm -rf $(BUILD)
