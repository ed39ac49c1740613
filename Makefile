# ds1928d — the two commands of the README:
#   make run    build and run the daemon on the simulated node
#   make run-canio   the daemon on bus canio against `ds1928-sim canio` over the virtual CAN bus
#   make test   build and run every test (warnings are errors in this build; `make build-test`
#               builds only)
# and for deployment:
#   make deb            build the Debian packages ds1928d, libds1928-dev, python3-ds1928 and
#                       (with linuxcnc-uspace-dev) linuxcnc-ds1928 (+ lintian)
#   make test-package   install them into a fresh Debian 12 root and check them there
# and the deeper checks (docs/testing.md):
#   make check-asan       the tests under ASan+UBSan (build-asan/; `make asan-build` builds only)
#   make check-tsan       the tests under TSan (build-tsan/)
#   make check-sanitize   both
#   make fuzz             every libFuzzer target for FUZZ_SECONDS each (clang, build-fuzz/)
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
# prometheus: promtool checks a scrape of the metrics endpoint. build-essential, libpcap-dev: the
# openPOWERLINK test peer (tests/peers/openpowerlink.sh). linuxcnc-uspace-dev, strace: the HAL
# component in the real LinuxCNC (tests/consumers); clang: the header's strict-C compile test.
TEST_DEPS  := $(BUILD_DEPS) rt-tests tshark iproute2 python3 util-linux passwd jq \
              qemu-system-x86 busybox-static cpio kmod xz-utils can-utils prometheus \
              build-essential libpcap-dev linuxcnc-uspace-dev strace clang
# dpkg-buildpackage and the Build-Depends of packaging/debian/control.
DEB_DEPS   := $(BUILD_DEPS) build-essential debhelper devscripts fakeroot lintian help2man \
              dh-python python3
# The LinuxCNC component's package (linuxcnc-ds1928) is built when linuxcnc-uspace-dev is
# installed; otherwise the build profile nolinuxcnc leaves it out.
DEB_PROFILES = $(if $(shell dpkg-query -W -f='$${Status}' linuxcnc-uspace-dev 2>/dev/null | \
                 grep -q 'install ok installed' && echo y),,-Pnolinuxcnc)
PKGTEST_DEPS := mmdebstrap util-linux systemd
# Where make deb builds: a copy of the source tree (the packaging expects debian/ at the top).
DEB_DIR    ?= build-deb

FUZZ_DEPS  := $(BUILD_DEPS) clang libclang-rt-14-dev
STRESS_DEPS := $(TEST_DEPS) stress-ng

# ccache when installed: the sanitizer and fuzz builds recompile the whole tree.
CCACHE     := $(shell command -v ccache 2>/dev/null)
LAUNCHER   := $(if $(CCACHE),-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
# The test programs reuse a precompiled Catch2 header (tests/CMakeLists.txt): ccache caches such
# compiles only with these sloppiness settings, and compiles them uncached without.
export CCACHE_SLOPPINESS ?= pch_defines,time_macros
FUZZ_SECONDS ?= 60
FUZZ_TARGETS := powerlink_frame sdo flatstream_receiver endat_reply control_request config_loader \
                canio_frame
# The sanitizer runtimes stop at the first report, so a finding fails its test.
ASAN_ENV   := ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:strict_string_checks=1 \
              UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
# The QEMU guest tests run the sanitized programs under the guest's software emulation: 3-4x the
# normal build's time (canio_qemu_e2e 213 s against 60 s) for code whose sanitized run is already
# in the SocketCAN port and virtual-bus tests. Label `timing`: tests that judge a hold or a phase
# in µs (PRC held at 1 ms, the LinuxCNC PLL), which the sanitizers' slowdown breaks, not memory
# safety. Both run in `make test`; SANITIZER_CTEST_ARGS= (empty) runs them under the sanitizers too.
SANITIZER_CTEST_ARGS ?= -LE 'qemu|timing'
# The test builds' debug information: line tables (file:line in every report and backtrace) at
# a fraction of -g's compile time (CMakeLists.txt, DS1928_DEBUG_INFO). TEST_DEBUG_INFO= : -g.
TEST_DEBUG_INFO ?= -DDS1928_DEBUG_INFO=-g1
TSAN_ENV   := TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 suppressions=$(CURDIR)/tests/tsan.supp"

.PHONY: all build run run-canio test build-test asan-build deps-build deps-test deps-deb deb test-package deps-fuzz deps-stress \
        format clean bench check-asan check-tsan check-sanitize fuzz stress

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

deps-deb:
	$(call ensure_packages,$(DEB_DEPS))

# The packages are built from a copy of the working tree with packaging/debian as debian/, so the
# tree itself stays as it is; the .debs, .buildinfo and .changes land in $(DEB_DIR)/.
deb: deps-deb
	rm -rf $(DEB_DIR)/src $(DEB_DIR)/*.deb $(DEB_DIR)/*.changes $(DEB_DIR)/*.buildinfo
	mkdir -p $(DEB_DIR)/src
	tar -C . --exclude-vcs --exclude='./build*' --exclude='./obj-*' -cf - . | tar -C $(DEB_DIR)/src -xf -
	cp -r packaging/debian $(DEB_DIR)/src/debian
	# ccache's compiler wrappers when installed: a rebuild of the same tree is fast.
	cd $(DEB_DIR)/src && PATH="$$(test -d /usr/lib/ccache && echo /usr/lib/ccache:)$$PATH" \
	  dpkg-buildpackage -us -uc -b -j$(JOBS) $(DEB_PROFILES)
	lintian --fail-on error,warning --info --display-info $(DEB_DIR)/*.changes

# Installs the packages into a fresh Debian 12 root (mmdebstrap; the base root is cached in
# $(DEB_DIR)/) and checks files, users, groups, units and configuration (tests/package/).
test-package: deb
	$(call ensure_packages,$(PKGTEST_DEPS))
	tests/package/install_test.sh $(DEB_DIR)

deps-fuzz:
	$(call ensure_packages,$(FUZZ_DEPS))

deps-stress:
	$(call ensure_packages,$(STRESS_DEPS))

$(BUILD)/CMakeCache.txt:
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=$(BUILD_TYPE) $(LAUNCHER)

build: deps-build $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) -j $(JOBS)

run: build
	./$(BUILD)/daemon/ds1928d --config $(CONFIG)

# The simulated CAN-I/O node runs in the background on the virtual bus of config/canio-sim.yaml
# and stops with the daemon (Ctrl-C); the bus (/dev/shm/ds1928-vcan.ds1928-sim, mode 0600) is
# removed after both, so the next run, as any user, creates it afresh.
CANIO_CONFIG ?= config/canio-sim.yaml
run-canio: build
	./$(BUILD)/tools/ds1928-sim/ds1928-sim canio --virtual ds1928-sim --config $(CANIO_CONFIG) & \
	  sim=$$!; trap 'kill $$sim 2>/dev/null; wait $$sim 2>/dev/null; rm -f /dev/shm/ds1928-vcan.ds1928-sim' EXIT INT TERM; \
	  ./$(BUILD)/daemon/ds1928d --config $(CANIO_CONFIG)

# The developer/CI build keeps zero warnings: DS1928_WERROR=ON here only (Release and package
# builds leave it off, so a newer compiler's new warning does not break them).
# `make build-test` is the build half alone (CI times the halves apart).
build-test: deps-test
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=$(BUILD_TYPE) -DDS1928_WERROR=ON $(TEST_DEBUG_INFO) $(LAUNCHER)
	cmake --build $(BUILD) -j $(JOBS)

test: build-test
	@# ctest names skipped tests without their reason: list each one's SKIP line after the summary.
	cd $(BUILD) || exit 1; rc=0; ctest --output-on-failure --timeout 900 -j 2 \
	  --output-junit "$$PWD/Testing/junit.xml" || rc=$$?; \
	  python3 $(CURDIR)/tests/ctest/skipped_reasons.py Testing/junit.xml || true; exit $$rc

# Sanitizer builds: their own build directories, the same ctest suite (unit and integration).
asan-build: deps-test
	cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DDS1928_SANITIZE=address,undefined $(TEST_DEBUG_INFO) $(LAUNCHER)
	cmake --build build-asan -j $(JOBS)

check-asan: asan-build
	cd build-asan && $(ASAN_ENV) ctest --output-on-failure --timeout 900 -j 2 $(SANITIZER_CTEST_ARGS)

check-tsan: deps-test
	cmake -S . -B build-tsan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DDS1928_SANITIZE=thread $(TEST_DEBUG_INFO) $(LAUNCHER)
	cmake --build build-tsan -j $(JOBS)
	cd build-tsan && $(TSAN_ENV) ctest --output-on-failure --timeout 900 -j 2 $(SANITIZER_CTEST_ARGS)

check-sanitize: check-asan check-tsan

# libFuzzer: each target FUZZ_SECONDS, starting from the committed seeds (fuzz/corpus/<name>);
# new inputs go to build-fuzz/corpus/<name>, crashers to build-fuzz/crash-<name>-*.
fuzz: deps-fuzz
	CC=clang CXX=clang++ cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=RelWithDebInfo -DDS1928_FUZZ=ON $(LAUNCHER)
	cmake --build build-fuzz -j $(JOBS) --target $(addprefix fuzz_,$(FUZZ_TARGETS))
	@set -e; for t in $(FUZZ_TARGETS); do \
	  mkdir -p build-fuzz/corpus/$$t; \
	  echo "== fuzz_$$t ($(FUZZ_SECONDS) s)"; \
	  ./build-fuzz/fuzz/fuzz_$$t -max_total_time=$(FUZZ_SECONDS) -print_final_stats=1 \
	    -artifact_prefix=build-fuzz/crash-$$t- build-fuzz/corpus/$$t fuzz/corpus/$$t; \
	done

# The test suite RUNS times in a row under `stress-ng --cpu 2` (tests/stress-repeat.sh).
RUNS ?= 20
stress: deps-stress build
	tests/stress-repeat.sh $(BUILD) $(RUNS)

bench: deps-test build
	./bench/run-all.sh $(BUILD)

format:
	find daemon include src tools tests bench -name '*.[ch]pp' -o -name '*.[ch]' | xargs clang-format -i

clean:
	rm -rf $(BUILD) $(DEB_DIR) build-asan build-tsan build-fuzz
