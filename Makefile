# The two commands of the README: `make demo` and `make test`. Both install what they need first.
JOBS ?= $(shell nproc)
# libopenvdb-dev reads .vdb volumes; its headers include Boost's, which Debian's package does not pull in (libboost-dev).
DEPS := build-essential cmake pkg-config zlib1g-dev libstb-dev libembree-dev libarchive-dev clang libclang-rt-14-dev \
        libassimp-dev libdeflate-dev python3-dev python3-cffi python3-numpy python3-pytest python3-pip python3-setuptools \
        openmpi-bin libopenmpi-dev \
        libsdl2-dev xvfb xauth \
        libopenexr-dev libopenvdb-dev libboost-dev
SUDO := $(shell [ "$$(id -u)" -eq 0 ] || echo sudo)

.PHONY: all deps release asan tsan demo test test-release test-asan test-tsan test-fuzz fuzz bench install clean

all: release

deps:
	@missing=""; for p in $(DEPS); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing:$$missing"; \
	  $(SUDO) apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends $$missing; \
	fi

release: deps
	cmake --preset release >/dev/null
	cmake --build --preset release -j $(JOBS)

asan: deps
	cmake --preset asan >/dev/null
	cmake --build --preset asan -j $(JOBS)

demo: release
	./build/release/raypack render -o raypack-demo.png
	@echo "wrote raypack-demo.png"

test-release: release
	ctest --preset release -j $(JOBS)

test-asan: asan
	ctest --preset asan -j $(JOBS)

# libFuzzer (clang) on every parser for FUZZ_SECONDS each, two at a time, after replaying the past
# crash reproducers; prints executions per parser (tests/fuzz/run.sh). CI: 60 s each.
FUZZ_SECONDS ?= 60
fuzz: deps
	cmake --preset fuzz >/dev/null
	cmake --build --preset fuzz -j $(JOBS)
	FUZZ_SECONDS=$(FUZZ_SECONDS) FUZZ_JOBS=$(JOBS) tests/fuzz/run.sh

test-fuzz: fuzz

# ThreadSanitizer over the threaded tests (builds, renders, the CLI, bench; CMakePresets.json's
# tsan test filter), clean: suppressions only for documented false positives (tests/tsan.supp).
tsan: deps
	cmake --preset tsan >/dev/null
	cmake --build --preset tsan -j $(JOBS)

test-tsan: tsan
	ctest --preset tsan -j $(JOBS)

test: test-release test-asan test-tsan test-fuzz

bench: release
	./build/release/raypack bench

# `make install PREFIX=/opt/raypack`: headers, libraries, the command, man page, pkg-config and CMake files.
PREFIX ?= /usr/local
install: release
	cmake --install build/release --prefix $(PREFIX)

clean:
	rm -rf build
