# Two commands do everything on a fresh Debian 12 machine:
#   make demo   install what is missing, build, run the main job on the project's default model
#   make test   install what is missing, build, run the whole test suite
BUILD ?= build
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?=
LIDEF = $(BUILD)/app/lidef
DEMO_OUT ?= out/demo

.PHONY: all deps configure build demo test bench clean format

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

bench: build
	@bash scripts/bench.sh $(BUILD)

format:
	@find deform analysis app opencl gui tests bench -name '*.cpp' -o -name '*.h' | xargs clang-format -i

clean:
	rm -rf $(BUILD)
