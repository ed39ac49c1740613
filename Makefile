# ds1928d — the two commands of the README:
#   make run    build and run the daemon on the simulated node
#   make run-canio   the daemon on bus canio against `ds1928-sim canio` over the virtual CAN bus
#   make test   build and run every test
# Each installs the Debian packages it needs when they are missing (as root), or
# prints the exact apt-get line to run.

BUILD      ?= build
BUILD_TYPE ?= RelWithDebInfo
CONFIG     ?= config/simulated.yaml
JOBS       ?= $(shell nproc)

BUILD_DEPS := cmake make g++ pkg-config libyaml-cpp-dev libspdlog-dev libfmt-dev libboost-dev \
              catch2 nlohmann-json3-dev libcli11-dev libsystemd-dev
# qemu-system-x86 … can-utils: the real-kernel CAN test (tests/canio/qemu), which also downloads
# Debian's linux-image package into the build tree with apt-get download.
TEST_DEPS  := $(BUILD_DEPS) rt-tests tshark iproute2 python3 \
              qemu-system-x86 busybox-static cpio kmod xz-utils can-utils

.PHONY: all build run run-canio test deps-build deps-test format clean bench

all: build

define ensure_packages
	@missing=""; for p in $(1); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    echo "Installing missing Debian packages:$$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing || exit 1; \
	  else \
	    echo "Missing Debian packages. Run as root:"; \
	    echo "  apt-get update && apt-get install -y$$missing"; \
	    exit 1; \
	  fi; \
	fi
endef

deps-build:
	$(call ensure_packages,$(BUILD_DEPS))

deps-test:
	$(call ensure_packages,$(TEST_DEPS))

$(BUILD)/CMakeCache.txt:
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=$(BUILD_TYPE)

build: deps-build $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) -j $(JOBS)

run: build
	./$(BUILD)/daemon/ds1928d --config $(CONFIG)

# The simulated CAN-I/O node runs in the background on the virtual bus of config/canio-sim.yaml
# and stops with the daemon (Ctrl-C).
CANIO_CONFIG ?= config/canio-sim.yaml
run-canio: build
	./$(BUILD)/tools/ds1928-sim/ds1928-sim canio --virtual ds1928-sim --config $(CANIO_CONFIG) & \
	  sim=$$!; trap 'kill $$sim 2>/dev/null; wait $$sim 2>/dev/null' EXIT INT TERM; \
	  ./$(BUILD)/daemon/ds1928d --config $(CANIO_CONFIG)

test: deps-test build
	cd $(BUILD) && ctest --output-on-failure --timeout 900 -j 2

bench: deps-test build
	./bench/run-all.sh $(BUILD)

format:
	find daemon include src tools tests bench -name '*.[ch]pp' -o -name '*.[ch]' | xargs clang-format -i

clean:
	rm -rf $(BUILD)
