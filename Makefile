# heatvox: make (library + command), make check, make bench, make demo,
# make install PREFIX=..., make sanitize, make format.

PREFIX  ?= /usr/local
BUILD   ?= build
CC      ?= cc
CXX     ?= g++
OPT     ?= -O3
SAN     ?=

ifeq ($(SAN),1)
OPT     := -O1 -g -fno-omit-frame-pointer
SANFLAGS := -fsanitize=address,undefined -fno-sanitize-recover=undefined
endif

WARN     := -Wall -Wextra -Wno-unused-parameter
CPPFLAGS += -Iinclude -Isrc -I$(BUILD)/gen -D_GNU_SOURCE -DCL_TARGET_OPENCL_VERSION=120
CFLAGS   += -std=c11 $(OPT) $(WARN) -fPIC -fopenmp $(SANFLAGS)
CXXFLAGS += -std=c++17 $(OPT) $(WARN) -fPIC -fopenmp $(SANFLAGS) -I/usr/include/OpenEXR
LDLIBS   += -lopenvdb -ltbb -lImath-3_1 -lOpenEXRCore-3_1 -lpng \
            -lfftw3_threads -lfftw3f_threads -lfftw3 -lfftw3f -lOpenCL -lz -lm -lpthread
LDFLAGS  += -fopenmp $(SANFLAGS)

# Debian 12 packages the build and tests need; installed once when missing.
DEB_PKGS := build-essential pkg-config check libfftw3-dev libopenvdb-dev libboost-dev libopenvdb-tools \
            python3-openvdb libtbb-dev libimath-dev libopenexr-dev libpng-dev \
            ocl-icd-opencl-dev opencl-headers pocl-opencl-icd zlib1g-dev python3-numpy

C_SRC   := $(sort $(wildcard src/*/*.c))
CXX_SRC := $(sort $(wildcard src/*/*.cpp))
CL_SRC  := $(sort $(wildcard kernels/*.cl))
OBJ     := $(C_SRC:%.c=$(BUILD)/obj/%.o) $(CXX_SRC:%.cpp=$(BUILD)/obj/%.o) $(BUILD)/obj/gen/kernels.o
TESTS   := $(patsubst tests/%.c,$(BUILD)/tests/%,$(sort $(wildcard tests/check_*.c)))
TESTLIB := $(patsubst %.c,$(BUILD)/obj/%.o,$(wildcard tests/testlib.c))
STAMP   := $(BUILD)/.deps-ok

LIB_A   := $(BUILD)/libheatvox.a
LIB_SO  := $(BUILD)/libheatvox.so
BIN     := $(BUILD)/heatvox

.PHONY: all deps check sanitize bench demo install format clean
.SECONDARY:
all: $(LIB_A) $(LIB_SO) $(BIN)

deps: $(STAMP)
$(STAMP): Makefile
	@missing=""; for p in $(DEB_PKGS); do \
	  dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null | grep -q '^install ok installed' || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    echo "heatvox: installing Debian packages:$$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing || exit 1; \
	  else \
	    echo "heatvox: missing Debian packages. Run as root:"; \
	    echo "  apt-get install -y$$missing"; exit 1; \
	  fi; \
	fi
	@mkdir -p $(BUILD) && touch $@

$(BUILD)/gen/kernels.c: $(CL_SRC) Makefile | $(STAMP)
	@mkdir -p $(dir $@)
	@{ echo '/* Generated from the OpenCL sources in kernels/ by the Makefile: do not edit. */'; \
	   echo '#include <stddef.h>'; \
	   for f in $(CL_SRC); do \
	     n=$$(basename $$f .cl | tr -c 'a-zA-Z0-9_\n' _); \
	     echo "const char hv_kernel_$${n}[] ="; \
	     sed -e 's/\\/\\\\/g' -e 's/"/\\"/g' -e 's/^/"/' -e 's/$$/\\n"/' $$f; \
	     echo ';'; \
	   done; \
	   echo 'const char *const hv_kernel_sources[] = {'; \
	   for f in $(CL_SRC); do n=$$(basename $$f .cl | tr -c 'a-zA-Z0-9_\n' _); echo "  hv_kernel_$${n},"; done; \
	   echo '  NULL};'; \
	   echo 'const char *const hv_kernel_names[] = {'; \
	   for f in $(CL_SRC); do echo "  \"$$(basename $$f)\","; done; \
	   echo '  NULL};'; } > $@

$(BUILD)/obj/gen/kernels.o: $(BUILD)/gen/kernels.c
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -c $< -o $@

$(BUILD)/obj/%.o: %.c | $(STAMP)
	@mkdir -p $(dir $@)
	$(CC) $(CPPFLAGS) $(CFLAGS) -MMD -MP -c $< -o $@

$(BUILD)/obj/%.o: %.cpp | $(STAMP)
	@mkdir -p $(dir $@)
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) -MMD -MP -c $< -o $@

$(LIB_A): $(OBJ)
	@rm -f $@
	ar rcs $@ $^

$(LIB_SO): $(OBJ)
	$(CXX) -shared -o $@ $^ $(LDFLAGS) $(LDLIBS)

$(BIN): $(BUILD)/obj/tools/heatvox.o $(patsubst %.c,$(BUILD)/obj/%.o,$(filter-out tools/heatvox.c,$(wildcard tools/*.c))) $(LIB_A)
	$(CXX) -o $@ $^ $(LDFLAGS) $(LDLIBS)

# Independent readers the tests compare against (OpenEXR's C++ library).
TEST_HELPERS := $(BUILD)/tests/exr_values
$(BUILD)/tests/exr_values: tests/exr_values.cpp | $(STAMP)
	@mkdir -p $(dir $@)
	$(CXX) -std=c++17 -O2 $(WARN) -I/usr/include/OpenEXR -I/usr/include/Imath $< -o $@ \
	  -lOpenEXR-3_1 -lIex-3_1 -lImath-3_1

$(BUILD)/tests/%: $(BUILD)/obj/tests/%.o $(TESTLIB) $(LIB_A)
	@mkdir -p $(dir $@)
	$(CXX) -o $@ $^ $(LDFLAGS) $$(pkg-config --libs check) $(LDLIBS)

# Each suite sets Check's no-fork mode itself (whatever CK_FORK says): OpenVDB
# (log4cplus/TBB threads) and OpenCL contexts hang forked children (NOTES §5).
# `timeout` stands in for Check's. The OpenCL solver suite runs a second time
# as on a device without fp64 (float kernels, double correction on the host):
# the run named fp32:SUITE; the multigrid suite a second time without its
# AVX-512 kernels (HV_NO512=1, the path of other CPUs): no512:SUITE.
CHECK_RUNS := $(TESTS) $(patsubst %,fp32:%,$(filter %/check_opencl,$(TESTS))) \
              $(patsubst %,no512:%,$(filter %/check_mg,$(TESTS)))
check: all $(TESTS) $(TEST_HELPERS)
	@pass=0; fail=0; skip=0; bad=""; skips=$(BUILD)/tests/skipped.txt; : > $$skips; \
	for run in $(CHECK_RUNS); do \
	  t=$${run#*:}; log=$$t.log; fp64=$${HEATVOX_OPENCL_FP64-}; no512=$${HV_NO512-}; \
	  case $$run in fp32:*) log=$$t.fp32.log; fp64=0;; no512:*) log=$$t.no512.log; no512=1;; esac; \
	  echo "== $$run"; \
	  HV_NO512=$$no512 HEATVOX_OPENCL_FP64=$$fp64 GOMP_SPINCOUNT=$${GOMP_SPINCOUNT:-1000} HEATVOX_SHARED=$${HEATVOX_SHARED:-../shared} timeout 900 $$t > $$log 2>&1; rc=$$?; cat $$log; \
	  line=$$(grep -E '^[0-9]+%: Checks: ' $$log | tail -n 1); \
	  c=$$(echo "$$line" | sed -E 's/.*Checks: ([0-9]+).*/\1/'); \
	  f=$$(echo "$$line" | sed -E 's/.*Failures: ([0-9]+), Errors: ([0-9]+).*/\1+\2/'); \
	  if [ -z "$$line" ]; then fail=$$((fail+1)); bad="$$bad $$run(rc=$$rc)"; continue; fi; \
	  s=$$(grep -c '^SKIP: ' $$log); n=$$(grep -c '^NOT RUN: ' $$log); \
	  grep -E '^(SKIP|NOT RUN): ' $$log | sed "s|^|  $$run: |" >> $$skips; \
	  f=$$(($$f)); pass=$$((pass + c - f - s)); fail=$$((fail + f)); skip=$$((skip + s + n)); \
	  if [ $$rc -ne 0 ] || [ $$f -ne 0 ]; then bad="$$bad $$run"; fi; \
	done; \
	echo; [ ! -s $$skips ] || { echo "skipped:"; cat $$skips; }; \
	[ -z "$$bad" ] || echo "failing suites:$$bad"; \
	echo "check: $$pass passed, $$fail failed, $$skip skipped"; \
	[ -z "$$bad" ]

sanitize:
	$(MAKE) BUILD=build-san SAN=1 check \
	  ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
	  LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan.supp

bench: all
	@sh tools/bench.sh $(BIN)

demo: all
	@sh tools/demo.sh $(BIN)

install: all
	install -d $(DESTDIR)$(PREFIX)/lib $(DESTDIR)$(PREFIX)/include/heatvox $(DESTDIR)$(PREFIX)/bin $(DESTDIR)$(PREFIX)/lib/pkgconfig
	install -m 644 $(LIB_A) $(DESTDIR)$(PREFIX)/lib/
	install -m 755 $(LIB_SO) $(DESTDIR)$(PREFIX)/lib/
	install -m 644 include/heatvox/*.h $(DESTDIR)$(PREFIX)/include/heatvox/
	install -m 755 $(BIN) $(DESTDIR)$(PREFIX)/bin/
	sed -e 's|@PREFIX@|$(PREFIX)|' -e 's|@VERSION@|'$$(sed -n 's/#define HV_VERSION_STRING "\(.*\)"/\1/p' include/heatvox/core.h)'|' \
	  heatvox.pc.in > $(DESTDIR)$(PREFIX)/lib/pkgconfig/heatvox.pc

format:
	clang-format -i $(C_SRC) $(CXX_SRC) $(wildcard include/heatvox/*.h src/*/*.h tools/*.c tests/*.c)

clean:
	rm -rf build build-san out

-include $(shell find $(BUILD)/obj -name '*.d' 2>/dev/null)
