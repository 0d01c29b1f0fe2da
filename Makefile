# cnc_bridge: the commands of the README.
#   make demo        set up, build, run the simulated cell (GUI=1 opens rviz)
#   make test        set up, build, run every test; ends with "N passed, N failed"
#   make build       set up and build only
#   make bench       run the benchmarks (bench/README.md)
GUI ?= 0

.PHONY: all setup build test demo bench clean
all: build

setup:
	@scripts/setup.sh

build: setup
	@scripts/build.sh

test: setup
	@scripts/test.sh

demo: build
	@GUI=$(GUI) scripts/demo.sh

bench: build
	@bench/run_all.sh

clean:
	rm -rf .build .build-asan
