# ds1928d — the two commands of the README:
#   make run    build and run the daemon on the simulated node
#   make test   build and run every test
# and for deployment:
#   make deb            build the Debian packages ds1928d and libds1928-dev (+ lintian)
#   make test-package   install them into a fresh Debian 12 root and check them there
# Each installs the Debian packages it needs when they are missing (as root), or
# prints the exact apt-get line to run.

BUILD      ?= build
BUILD_TYPE ?= RelWithDebInfo
CONFIG     ?= config/simulated.yaml
JOBS       ?= $(shell nproc)

BUILD_DEPS := cmake make g++ pkg-config libyaml-cpp-dev libspdlog-dev libfmt-dev libboost-dev \
              catch2 nlohmann-json3-dev libcli11-dev libsystemd-dev
TEST_DEPS  := $(BUILD_DEPS) rt-tests tshark iproute2 python3 util-linux passwd
# dpkg-buildpackage and the Build-Depends of packaging/debian/control.
DEB_DEPS   := $(BUILD_DEPS) build-essential debhelper devscripts fakeroot lintian help2man
PKGTEST_DEPS := mmdebstrap util-linux systemd
# Where make deb builds: a copy of the source tree (the packaging expects debian/ at the top).
DEB_DIR    ?= build-deb

.PHONY: all build run test deps-build deps-test deps-deb deb test-package format clean bench

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
	  dpkg-buildpackage -us -uc -b -j$(JOBS)
	lintian --fail-on error,warning --info --display-info $(DEB_DIR)/*.changes

# Installs the packages into a fresh Debian 12 root (mmdebstrap; the base root is cached in
# $(DEB_DIR)/) and checks files, users, groups, units and configuration (tests/package/).
test-package: deb
	$(call ensure_packages,$(PKGTEST_DEPS))
	tests/package/install_test.sh $(DEB_DIR)

$(BUILD)/CMakeCache.txt:
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=$(BUILD_TYPE)

build: deps-build $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) -j $(JOBS)

run: build
	./$(BUILD)/daemon/ds1928d --config $(CONFIG)

test: deps-test build
	cd $(BUILD) && ctest --output-on-failure --timeout 900 -j 2

bench: deps-test build
	./bench/run-all.sh $(BUILD)

format:
	find daemon include src tools tests bench -name '*.[ch]pp' -o -name '*.[ch]' | xargs clang-format -i

clean:
	rm -rf $(BUILD) $(DEB_DIR)
