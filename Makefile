# heatvox: make (library + command), make check, make bench, make demo,
# make install PREFIX=..., make sanitize, make format.

# Every target builds in parallel on all CPUs unless -j is given (at the top
# level only: sub-makes share its job server).
ifeq ($(MAKELEVEL)$(filter -j%,$(MAKEFLAGS)),0)
MAKEFLAGS += -j$(shell nproc 2>/dev/null || echo 2)
endif

PREFIX  ?= /usr/local
BUILD   ?= build
CC      ?= cc
CXX     ?= g++
OPT     ?= -O3
SAN     ?=

CXX_SANLIGHT := -g1 -fno-sanitize=alignment,null,object-size,vptr
ifeq ($(SAN),1)
OPT     := -O1 -g -fno-omit-frame-pointer
SANFLAGS := -fsanitize=address,undefined -fno-sanitize-recover=undefined
# The C++ files compile OpenVDB's and TBB's header templates, where UBSan's
# pointer checks (null, alignment, object size, vptr) instrument every member
# access and full debug information is large: GCC took 212 s on
# vdb_write.cpp with them, 83 s without them and with line tables alone
# (-g1, enough for the sanitizers' stack traces). ASan still checks every
# access there, and UBSan's arithmetic checks stay. The fuzzing and
# ThreadSanitizer builds (below) use the same flags for their C++ files.
CXX_SANFLAGS := $(CXX_SANLIGHT)
endif
# Two files only run OpenVDB's own algorithms: its mesher (vdb_volmesh.cpp,
# for vdb_mesh.cpp) and the benchmarks' OpenVDB reference. The sanitized
# builds (make sanitize, make tsan) compile them as OpenVDB itself is
# compiled, without instrumentation: under ASan their templates took 124 s
# and 131 s of GCC's time, half of what the whole build took.
VDB_ALGO_SRC := src/mesh/vdb_volmesh.cpp tools/bench/bench_ref_vdb.cpp

WARN     := -Wall -Wextra -Wno-unused-parameter
ifneq ($(SANFLAGS),)
$(VDB_ALGO_SRC:%.cpp=$(BUILD)/obj/%.o): override SANFLAGS :=
$(VDB_ALGO_SRC:%.cpp=$(BUILD)/obj/%.o): override CXX_SANFLAGS := -g1
endif
CPPFLAGS += -Iinclude -Isrc -I$(BUILD)/gen -D_GNU_SOURCE -DCL_TARGET_OPENCL_VERSION=120
CFLAGS   += -std=c11 $(OPT) $(WARN) -Werror=implicit-function-declaration -fPIC -fopenmp $(SANFLAGS)
CXXFLAGS += -std=c++17 $(OPT) $(WARN) -fPIC -fopenmp $(SANFLAGS) $(CXX_SANFLAGS) -I/usr/include/OpenEXR
# The library exports only what the public headers mark HV_API: its C code is
# compiled with hidden visibility, and the shared library's version script
# (src/heatvox.map) keeps the rest local. The OpenVDB shim (C++) keeps default
# visibility: OpenVDB's header templates hidden in a program crash
# openvdb::initialize() when the grid types are registered.
LIBFLAGS := -fvisibility=hidden
# The command uses the public API alone: include/ only, no src/.
TOOL_CPPFLAGS := -Iinclude -D_GNU_SOURCE
# assimp (the glTF, FBX, 3MF, COLLADA and X reader) through pkg-config; the
# fallback keeps the flags the same before `make deps` installs it.
ASSIMP_CFLAGS := $(shell pkg-config --cflags assimp 2>/dev/null)
ASSIMP_LIBS   := $(or $(shell pkg-config --libs assimp 2>/dev/null),-lassimp)
CPPFLAGS += $(ASSIMP_CFLAGS)
LDLIBS   += -lopenvdb -ltbb -lImath-3_1 -lOpenEXRCore-3_1 -lpng $(ASSIMP_LIBS) \
            -lfftw3_threads -lfftw3f_threads -lfftw3 -lfftw3f -lOpenCL -lz -lm -lpthread
LDFLAGS  += -fopenmp $(SANFLAGS)

# Debian 12 packages the build and tests need; installed once when missing.
DEB_PKGS := build-essential pkg-config check libfftw3-dev libopenvdb-dev libboost-dev libopenvdb-tools \
            python3-openvdb libtbb-dev libimath-dev libopenexr-dev libpng-dev \
            ocl-icd-opencl-dev opencl-headers pocl-opencl-icd zlib1g-dev python3-numpy clang-format \
            clang-14 libassimp-dev assimp-testmodels
# Those of CGAL's reference program alone (make bench), checked with a stamp
# of their own by the same rule.
CGAL_PKGS  := libcgal-dev libeigen3-dev
CGAL_STAMP  = $(BUILD)/.deps-cgal-ok

# MPI and PETSc (optional): where pkg-config finds PETSc (Debian's petsc-dev,
# with OpenMPI, hypre and parallel HDF5), the build links it and gains the
# petsc backend, HDF5 output and the DMDA API; HV_PETSC=0 leaves it out, and
# HV_PETSC=1 insists. `make mpi` installs them and builds with them into
# build-mpi/ (the MPI programs and tests too); `make mpi-check` runs the
# distributed tests under mpirun. The sanitizer and fuzzing builds leave PETSc
# out: MPI's own allocations would read as leaks, and mpi-check covers it.
MPI_BUILD ?= build-mpi
MPI_PKGS  := petsc-dev openmpi-bin python3-h5py
ifeq ($(origin HV_PETSC),undefined)
HV_PETSC  := $(shell pkg-config --exists PETSc ompi-c hdf5-openmpi 2>/dev/null && echo 1 || echo 0)
endif
ifeq ($(HV_PETSC),1)
CPPFLAGS += -DHV_HAVE_PETSC $(shell pkg-config --cflags PETSc ompi-c hdf5-openmpi 2>/dev/null)
LDLIBS   += $(shell pkg-config --libs PETSc ompi-c hdf5-openmpi 2>/dev/null)
endif

# The flags the objects were built with, written when they change (PETSc
# found or gone, another OPT): everything depending on them is rebuilt.
FLAGS_NOW := $(CC) $(CXX) $(CPPFLAGS) $(CFLAGS) $(CXXFLAGS) $(LIBFLAGS) $(TOOL_CPPFLAGS) $(LDFLAGS) $(LDLIBS)
FLAGS     := $(BUILD)/.flags
ifneq ($(file <$(FLAGS)),$(FLAGS_NOW))
$(shell mkdir -p $(BUILD))
$(file >$(FLAGS),$(FLAGS_NOW))
endif

C_SRC   := $(sort $(wildcard src/*/*.c src/*/*/*.c))
CXX_SRC := $(sort $(wildcard src/*/*.cpp src/*/*/*.cpp))
CL_SRC  := $(sort $(wildcard kernels/*.cl))
OBJ     := $(C_SRC:%.c=$(BUILD)/obj/%.o) $(CXX_SRC:%.cpp=$(BUILD)/obj/%.o) $(BUILD)/obj/gen/kernels.o
TESTS   := $(patsubst tests/%.c,$(BUILD)/tests/%,$(sort $(wildcard tests/check_*.c)))
TESTLIB := $(patsubst %.c,$(BUILD)/obj/%.o,$(wildcard tests/testlib.c))
# One stamp per package list: the MPI one (DEPS_TAG=-mpi, make mpi-deps) is
# checked even where the plain list's stamp is already there.
STAMP   := $(BUILD)/.deps-ok$(DEPS_TAG)

# The Python package (python/heatvox) goes beside the library, into Debian
# python3's site directory under PREFIX (for /usr/local one that Debian's
# Python searches); without python3 `make install` leaves it out.
PYTHON  ?= /usr/bin/python3
PY_SRC  := $(sort $(wildcard python/heatvox/*.py))
PYVER   := $(shell $(PYTHON) -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null)
PYDIR   := $(PREFIX)/lib/python$(PYVER)/dist-packages

VERSION := $(shell sed -n 's/^\#define HV_VERSION_STRING "\(.*\)"/\1/p' include/heatvox/core.h)
SOMAJOR := $(firstword $(subst ., ,$(VERSION)))
LIB_A   := $(BUILD)/libheatvox.a
LIB_SO  := $(BUILD)/libheatvox.so
LIB_SOV := $(BUILD)/libheatvox.so.$(VERSION)
BIN     := $(BUILD)/heatvox

.PHONY: all deps check sanitize bench demo install format format-check clean
.SECONDARY:
all: $(LIB_A) $(LIB_SO) $(BIN)

deps: $(STAMP)
$(CGAL_STAMP): DEB_PKGS = $(CGAL_PKGS)
$(STAMP) $(CGAL_STAMP): Makefile
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
	     echo "const char hv__kernel_$${n}[] ="; \
	     sed -e 's/\\/\\\\/g' -e 's/"/\\"/g' -e 's/^/"/' -e 's/$$/\\n"/' $$f; \
	     echo ';'; \
	   done; \
	   echo 'const char *const hv__kernel_sources[] = {'; \
	   for f in $(CL_SRC); do n=$$(basename $$f .cl | tr -c 'a-zA-Z0-9_\n' _); echo "  hv__kernel_$${n},"; done; \
	   echo '  NULL};'; \
	   echo 'const char *const hv__kernel_names[] = {'; \
	   for f in $(CL_SRC); do echo "  \"$$(basename $$f)\","; done; \
	   echo '  NULL};'; } > $@

$(BUILD)/obj/gen/kernels.o: $(BUILD)/gen/kernels.c $(FLAGS)
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) $(LIBFLAGS) -c $< -o $@

$(BUILD)/obj/src/%.o: src/%.c $(FLAGS) | $(STAMP)
	@mkdir -p $(dir $@)
	$(CC) $(CPPFLAGS) $(CFLAGS) $(LIBFLAGS) -MMD -MP -c $< -o $@


$(BUILD)/obj/tools/%.o: tools/%.c $(FLAGS) | $(STAMP)
	@mkdir -p $(dir $@)
	$(CC) $(TOOL_CPPFLAGS) $(CFLAGS) -MMD -MP -c $< -o $@

# C++ under tools/: the OpenVDB reference algorithms of the benchmarks
# (tools/bench/bench_ref_vdb.cpp), not part of the library. Public headers and
# OpenVDB's only; default visibility, like the library's OpenVDB shim.
# tools/bench/bench_ref_cgal.cpp is a program of its own (make bench, below).
TOOL_CXX_OBJ := $(patsubst %.cpp,$(BUILD)/obj/%.o,$(filter-out tools/bench/bench_ref_cgal.cpp,\
                  $(wildcard tools/*.cpp tools/bench/*.cpp)))
$(BUILD)/obj/tools/%.o: tools/%.cpp $(FLAGS) | $(STAMP)
	@mkdir -p $(dir $@)
	$(CXX) $(TOOL_CPPFLAGS) $(CXXFLAGS) -MMD -MP -c $< -o $@

$(BUILD)/obj/%.o: %.c $(FLAGS) | $(STAMP)
	@mkdir -p $(dir $@)
	$(CC) $(CPPFLAGS) $(CFLAGS) -MMD -MP -c $< -o $@

$(BUILD)/obj/%.o: %.cpp $(FLAGS) | $(STAMP)
	@mkdir -p $(dir $@)
	$(CXX) $(CPPFLAGS) $(CXXFLAGS) -MMD -MP -c $< -o $@

$(LIB_A): $(OBJ)
	@rm -f $@
	ar rcs $@ $^

# libheatvox.so.X.Y.Z with soname libheatvox.so.X, and the two links to it.
$(LIB_SOV): $(OBJ) src/heatvox.map $(FLAGS)
	$(CXX) -shared -Wl,-soname,libheatvox.so.$(SOMAJOR) -Wl,--no-undefined -Wl,--version-script,src/heatvox.map \
	  -o $@ $(OBJ) $(LDFLAGS) $(LDLIBS)

$(LIB_SO): $(LIB_SOV)
	ln -sf $(notdir $<) $(BUILD)/libheatvox.so.$(SOMAJOR)
	ln -sf $(notdir $<) $@

$(BIN): $(BUILD)/obj/tools/heatvox.o $(patsubst %.c,$(BUILD)/obj/%.o,$(filter-out tools/heatvox.c,$(wildcard tools/*.c tools/bench/*.c))) $(TOOL_CXX_OBJ) $(LIB_A)
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

# check_vdb also tests the reference algorithms of the benchmarks.
$(BUILD)/tests/check_vdb: $(BUILD)/obj/tests/check_vdb.o $(BUILD)/obj/tools/bench/bench_ref_vdb.o $(TESTLIB) $(LIB_A)
	@mkdir -p $(dir $@)
	$(CXX) -o $@ $^ $(LDFLAGS) $$(pkg-config --libs check) $(LDLIBS)

# check_points_sample tests the point sampler of the benchmarks.
$(BUILD)/tests/check_points_sample: $(BUILD)/obj/tests/check_points_sample.o \
                                    $(BUILD)/obj/tools/bench/points_sample.o $(TESTLIB) $(LIB_A)
	@mkdir -p $(dir $@)
	$(CXX) -o $@ $^ $(LDFLAGS) $$(pkg-config --libs check) $(LDLIBS)

# Each suite sets Check's no-fork mode itself (whatever CK_FORK says): OpenVDB
# (log4cplus/TBB threads) and OpenCL contexts hang forked children
# (docs/METHOD.md, "Testing notes").
# `timeout` stands in for Check's. The OpenCL suites (solver, device fields,
# extension, distance) run a second time as on a device without fp64 (float
# kernels, double correction on the host): the runs named SUITE.fp32; the multigrid suites a second time without their
# AVX-512 kernels (HV_NO512=1, the path of other CPUs): SUITE.no512; the aggregation suite a third time
# without the hand-written AVX2 ones either (HV_NOAVX2=1, the baseline C): SUITE.noavx2.
# Runs: each suite, tests/check_kernels.sh (every OpenCL program compiled
# offline as strict OpenCL C 1.2 and 3.0), tests/check_includes.py (the
# include map of src/README.md), the OpenCL ones again as on a device without
# fp64 (NAME.fp32), the multigrid ones again without AVX-512 (NAME.no512) and without AVX2 (NAME.noavx2). make -j runs them
# side by side, the longest first; tests/check_summary.sh prints each log in
# this order, then the totals.
CHECK_SLOW := check_batch check_faults check_mesh_out check_readme check_extend_cl check_sdf_tiles
CHECK_RUNS := $(filter $(CHECK_SLOW),$(notdir $(TESTS))) $(filter-out $(CHECK_SLOW),$(notdir $(TESTS))) \
              check_kernels check_includes \
              $(patsubst %,%.fp32,$(filter check_opencl check_opencl_device check_extend_cl check_distance_cl,$(notdir $(TESTS)))) \
              $(patsubst %,%.no512,$(filter check_mg check_mg_agg,$(notdir $(TESTS)))) \
              $(patsubst %,%.noavx2,$(filter check_mg_agg,$(notdir $(TESTS))))
RES := $(BUILD)/tests/results
# tests/check_readme builds the README's C example and tests/check_api a
# program linked shared and static against an installed copy: make check
# stages `make install` into $(BUILD)/stage first.
STAGE := $(BUILD)/stage
$(STAGE)/.installed: $(LIB_A) $(LIB_SO) $(BIN) $(wildcard include/heatvox/*.h) $(PY_SRC) heatvox.pc.in Makefile
	@mkdir -p $(STAGE)
	+@$(MAKE) --no-print-directory install PREFIX=$(CURDIR)/$(STAGE) DESTDIR= > $(STAGE)/install.log 2>&1 \
	  || { cat $(STAGE)/install.log; exit 1; }
	@touch $@

check: all $(TESTS) $(TEST_HELPERS) $(STAGE)/.installed
	@rm -rf $(RES) && mkdir -p $(RES)
	@{ ls -d /tmp/hv_* 2>/dev/null; grep -o ' /tmp/hv_[^ ]*' /proc/mounts; } | sort > $(RES)/tmp.before
	+@$(MAKE) --no-print-directory -k $(CHECK_RUNS:%=$(RES)/%.rc) || true
	@sh tests/check_summary.sh $(RES) $(CHECK_RUNS)

# Longer cases that make check shortens (HEATVOX_TEST_LONG=1): the EXR
# volumes of check_batch at every resolution.
.PHONY: check-long
check-long: all $(BUILD)/tests/check_batch $(TEST_HELPERS)
	HEATVOX_TEST_LONG=1 HEATVOX_TEST_DATA=$${HEATVOX_TEST_DATA:-../shared/meshes} $(BUILD)/tests/check_batch

# One run: its log, exit code and seconds under $(RES). Every build's runs
# share one PoCL kernel cache (POCL_CACHE): a kernel's binary depends on its
# source, options and device, not on how the host code was built, so make
# check after make sanitize compiles none again.
POCL_CACHE ?= $(CURDIR)/build/pocl-cache
$(RES)/%.rc:
	@mkdir -p $(POCL_CACHE)
	@run=$*; t=$(BUILD)/tests/$${run%%.*}; fp64=$${HEATVOX_OPENCL_FP64-}; no512=$${HV_NO512-}; \
	noavx2=$${HV_NOAVX2-}; \
	[ $$run != check_kernels ] || t="sh tests/check_kernels.sh $(BUILD)/kernels $(FZ_CC)"; \
	[ $$run != check_includes ] || t="python3 tests/check_includes.py"; \
	case $$run in *.fp32) fp64=0;; *.no512) no512=1;; *.noavx2) no512=1; noavx2=1;; esac; \
	t0=$$(date +%s%N); \
	HV_NO512=$$no512 HV_NOAVX2=$$noavx2 HEATVOX_OPENCL_FP64=$$fp64 GOMP_SPINCOUNT=$${GOMP_SPINCOUNT:-1000} \
	  POCL_CACHE_DIR=$${POCL_CACHE_DIR:-$(POCL_CACHE)} \
	  HEATVOX_TEST_DATA=$${HEATVOX_TEST_DATA:-../shared/meshes} timeout 900 $$t > $(RES)/$$run.log 2>&1; \
	rc=$$?; ms=$$(( ($$(date +%s%N) - t0) / 1000000 )); \
	echo "$$ms" > $(RES)/$$run.ms; echo $$rc > $@; \
	printf '== %-28s exit %d, %d.%01d s\n' $$run $$rc $$((ms / 1000)) $$((ms % 1000 / 100))

# ---- mpi: the petsc backend under mpirun ----
# Ranks 1 to 4 (oversubscribed on small machines); OpenMPI refuses root
# without the two variables.
MPI_RUN := OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1 \
           OMP_NUM_THREADS=1 mpirun --oversubscribe
.PHONY: mpi mpi-deps mpi-check
# Two passes: the packages first, then the build, whose flags come from
# pkg-config when its Makefile is read (a fresh machine has no PETSc before).
# With the packages installed first (make mpi-deps), the default build links
# PETSc too, and `make mpi-check MPI_BUILD=build` reuses it.
mpi-deps:
	+@$(MAKE) --no-print-directory BUILD=$(MPI_BUILD) HV_PETSC=1 DEPS_TAG=-mpi DEB_PKGS='$(DEB_PKGS) $(MPI_PKGS)' deps
	@pkg-config --exists PETSc ompi-c hdf5-openmpi || \
	  { echo "heatvox: pkg-config finds no PETSc, OpenMPI or parallel HDF5 after installing $(MPI_PKGS)"; exit 1; }
mpi: mpi-deps
	+@$(MAKE) --no-print-directory BUILD=$(MPI_BUILD) HV_PETSC=1 DEPS_TAG=-mpi DEB_PKGS='$(DEB_PKGS) $(MPI_PKGS)' \
	  all $(MPI_BUILD)/tests/mpi_solve $(MPI_BUILD)/tests/mpi_dmda $(MPI_BUILD)/advect_dmda \
	  $(MPI_BUILD)/bench_mpi
mpi-check: mpi
	@bad=""; for p in 1 2 3 4; do \
	  echo "== mpirun -n $$p mpi_solve"; \
	  $(MPI_RUN) -n $$p $(MPI_BUILD)/tests/mpi_solve || bad="$$bad mpi_solve($$p)"; \
	  echo "== mpirun -n $$p mpi_dmda"; \
	  $(MPI_RUN) -n $$p $(MPI_BUILD)/tests/mpi_dmda || bad="$$bad mpi_dmda($$p)"; \
	done; \
	echo "== tests/mpi/pipelines.py: distance and extend on 1 to 4 ranks, HDF5 output"; \
	$(PYTHON) tests/mpi/pipelines.py $(MPI_BUILD)/heatvox env $(MPI_RUN) || bad="$$bad pipelines"; \
	echo "== README.md: the Distributed runs examples"; \
	mkdir -p out; \
	sed -n '/^## Distributed runs/,/^## Library/p' README.md | \
	  awk '/^```sh/{f=1;next} /^```/{f=0} f' | \
	  sed -e 's|^mpirun --oversubscribe |$(MPI_RUN) |' -e '/^make mpi$$/d' -e '/^export /d' \
	    -e 's|build-mpi/|$(MPI_BUILD)/|g' > $(MPI_BUILD)/readme_mpi.sh; \
	bash -e -x $(MPI_BUILD)/readme_mpi.sh > $(MPI_BUILD)/readme_mpi.log 2>&1 || \
	  { tail -30 $(MPI_BUILD)/readme_mpi.log; bad="$$bad README"; }; \
	[ -z "$$bad" ] || { echo "mpi-check: failing:$$bad"; exit 1; }; \
	echo "mpi-check: mpi_solve, mpi_dmda and the pipelines on 1 to 4 ranks, and the README's distributed examples passed"
# The example simulation (tools/examples/advect_dmda.c), built as a user
# would: the installed-style include path and the library.
$(MPI_BUILD)/advect_dmda: tools/examples/advect_dmda.c $(LIB_A) | $(STAMP)
	$(CC) $(TOOL_CPPFLAGS) $(CPPFLAGS) $(CFLAGS) $< -o $@ $(LIB_A) $(LDFLAGS) -lstdc++ $(LDLIBS)
$(MPI_BUILD)/bench_mpi: tools/mpi/bench_mpi.c $(LIB_A) | $(STAMP)
	$(CC) $(TOOL_CPPFLAGS) $(CPPFLAGS) $(CFLAGS) $< -o $@ $(LIB_A) $(LDFLAGS) -lstdc++ $(LDLIBS)
$(MPI_BUILD)/tests/mpi_%: tests/mpi/mpi_%.c tests/mpi/mpi_cases.h $(LIB_A) | $(STAMP)
	@mkdir -p $(dir $@)
	$(CC) $(CPPFLAGS) $(CFLAGS) $< -o $@ $(LIB_A) $(LDFLAGS) -lstdc++ $(LDLIBS)

sanitize:
	$(MAKE) BUILD=build-san SAN=1 HV_PETSC=0 check \
	  ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
	  LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan.supp

# CGAL's Poisson surface reconstruction, the reference of `heatvox bench
# points` (tools/bench/bench_ref_cgal.cpp): a program of its own, built by
# make bench only, since CGAL's headers take a minute to compile. Its Debian
# packages (CGAL_PKGS) are installed, or asked for, by the deps rule. CGAL
# needs -frounding-math for its exact predicates under GCC; NDEBUG drops its
# assertions, as CGAL's release builds do.
REF_CGAL := $(BUILD)/bench_ref_cgal
.PHONY: bench-ref-cgal
bench-ref-cgal: $(REF_CGAL)
$(REF_CGAL): tools/bench/bench_ref_cgal.cpp $(FLAGS) | $(CGAL_STAMP)
	$(CXX) -std=c++17 $(OPT) $(WARN) -frounding-math -DNDEBUG -DCGAL_EIGEN3_ENABLED \
	  -I/usr/include/eigen3 $< -o $@ -lgmp -lmpfr

bench: all $(REF_CGAL)
	@sh tools/bench/bench.sh $(BIN)

demo: all
	@sh tools/demo.sh $(BIN)

install: all
	install -d $(DESTDIR)$(PREFIX)/lib $(DESTDIR)$(PREFIX)/include/heatvox $(DESTDIR)$(PREFIX)/bin $(DESTDIR)$(PREFIX)/lib/pkgconfig
	install -m 644 $(LIB_A) $(DESTDIR)$(PREFIX)/lib/
	install -m 755 $(LIB_SOV) $(DESTDIR)$(PREFIX)/lib/
	ln -sf libheatvox.so.$(VERSION) $(DESTDIR)$(PREFIX)/lib/libheatvox.so.$(SOMAJOR)
	ln -sf libheatvox.so.$(VERSION) $(DESTDIR)$(PREFIX)/lib/libheatvox.so
	install -m 644 include/heatvox/*.h $(DESTDIR)$(PREFIX)/include/heatvox/
	install -m 755 $(BIN) $(DESTDIR)$(PREFIX)/bin/
	sed -e 's|@PREFIX@|$(PREFIX)|' -e 's|@VERSION@|$(VERSION)|' -e 's|@ASSIMP_LIBS@|$(ASSIMP_LIBS)|' \
	  -e 's|@REQUIRES@|$(if $(filter 1,$(HV_PETSC)),Requires.private: PETSc ompi-c hdf5-openmpi,)|' \
	  heatvox.pc.in > $(DESTDIR)$(PREFIX)/lib/pkgconfig/heatvox.pc
ifneq ($(PYVER),)
	install -d $(DESTDIR)$(PYDIR)/heatvox
	install -m 644 $(PY_SRC) $(DESTDIR)$(PYDIR)/heatvox/
	printf '# Written by make install: the library this package loads.\nLIBDIR = "%s"\nSONAME = "%s"\n' \
	  '$(PREFIX)/lib' 'libheatvox.so.$(SOMAJOR)' > $(DESTDIR)$(PYDIR)/heatvox/_install.py
endif
	@echo "heatvox $(VERSION) installed in $(DESTDIR)$(PREFIX):"
	@echo "  library  $(DESTDIR)$(PREFIX)/lib/libheatvox.so.$(VERSION) (soname libheatvox.so.$(SOMAJOR)) and libheatvox.a"
	@echo "  headers  $(DESTDIR)$(PREFIX)/include/heatvox/"
	@echo "  command  $(DESTDIR)$(PREFIX)/bin/heatvox"
	@echo "  pkg-config file $(DESTDIR)$(PREFIX)/lib/pkgconfig/heatvox.pc"
ifneq ($(PYVER),)
	@echo "  python   $(DESTDIR)$(PYDIR)/heatvox (import heatvox; PYTHONPATH=$(PYDIR) where $(PYTHON) does not search it)"
else
	@echo "  python   not installed: no $(PYTHON)"
endif
	@case "$(PREFIX)" in /usr|/usr/local) echo "Run ldconfig (as root) once so that programs find the shared library.";; \
	  *) echo "Build with PKG_CONFIG_PATH=$(PREFIX)/lib/pkgconfig and link with -Wl,-rpath,$(PREFIX)/lib (or add $(PREFIX)/lib to /etc/ld.so.conf.d/ and run ldconfig).";; esac

# make format lays out every C and C++ source by .clang-format; make
# format-check (run by CI) fails, listing the places, when one differs.
FORMAT_SRC = $(sort $(C_SRC) $(CXX_SRC) $(wildcard include/heatvox/*.h src/*/*.h src/*/*/*.h tools/*.c tools/*.h \
               tools/*.cpp tools/bench/*.c tools/bench/*.h tools/bench/*.cpp tests/*.c tests/*.h tests/*.cpp tests/fuzz/*.c tests/fuzz/*.h))
format: | $(STAMP)
	clang-format -i $(FORMAT_SRC)

format-check: | $(STAMP)
	@clang-format --dry-run --Werror $(FORMAT_SRC) && echo "format-check: $(words $(FORMAT_SRC)) files as .clang-format lays them out"

clean:
	rm -rf build build-san build-mpi out

# ---- fuzz (tests/fuzz/): libFuzzer targets with ASan and UBSan, clang 14 ----
# make fuzz FUZZ_SECONDS=N builds the library with clang into build-fz/ (the
# build rules above, run with BUILD=build-fz and clang's flags), links one
# target per parser, generates seed corpora and runs each target for N seconds.
# It fails when a target finds a crash (also one that -ignore_crashes let
# pass: any new file under build-fz/crashes/NAME/); the input is kept in
# build-fz/crashes/NAME/ (copy small ones into tests/fuzz/regress/NAME/, which
# check_fuzz_regress replays). FUZZ_TARGETS picks targets, FUZZ_FLAGS adds
# libFuzzer options (e.g. -fork=1 -ignore_ooms=1 to go on past an OOM);
# FUZZ_MAX_LEN bounds inputs (the make-scenes seeds are larger: they are cut,
# which keeps the text readers near 10^4 runs per second instead of 10^3).
# OpenVDB and OpenEXR themselves are not instrumented.
FZ           := build-fz
FUZZ_SECONDS ?= 60
FUZZ_TARGETS ?= obj ply stl off mesh points assimp svg curves npy exr vdb
FUZZ_FLAGS   ?=
FUZZ_MAX_LEN ?= 65536
FUZZ_PKGS    := clang-14 libclang-rt-14-dev libomp-14-dev
ASSIMP_MODELS ?= /usr/share/assimp/models
FZ_CC        := clang-14
FZ_CXX       := clang++-14
FZ_SAN       := -fsanitize=address,undefined -fno-sanitize-recover=undefined
FZ_OPT       := -O1 -g -fno-omit-frame-pointer
FZ_SUBMAKE    = $(MAKE) BUILD=$(FZ) HV_PETSC=0 CC=$(FZ_CC) CXX=$(FZ_CXX) OPT='$(FZ_OPT)' \
                SANFLAGS='$(FZ_SAN) -fsanitize=fuzzer-no-link' DEB_PKGS='$(DEB_PKGS) $(FUZZ_PKGS)'
FZ_BINS      := $(patsubst %,$(FZ)/fuzz/fuzz_%,$(FUZZ_TARGETS))
FZ_ASAN      := detect_leaks=1:allocator_may_return_null=1
FZ_RUNENV    := ASAN_OPTIONS=$(FZ_ASAN) \
                UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 \
                LSAN_OPTIONS=suppressions=$(CURDIR)/tests/fuzz/lsan.supp

# Header code of OpenVDB and TBB compiled into the shim trips two UBSan checks
# on its own: TBB's concurrent_hash_map casts sentinel pointers such as 0x3
# (alignment), and OpenVDB 10's RootNode::readTopology reads a tile's
# "active" flag straight from the file into a bool (bool; a corrupt byte is
# UB there). Neither is heatvox's code.
# Like make sanitize's, the C++ files leave out UBSan's pointer checks and
# keep line tables alone (CXX_SANLIGHT above).
$(CXX_SRC:%.cpp=$(FZ)/obj/%.o): CXXFLAGS += -fno-sanitize=bool $(CXX_SANLIGHT)

# The targets link the parsers' objects alone: those of core, io and mesh but
# the .vdb writer and the mesher (vdb_write.cpp, vdb_mesh.cpp and
# vdb_volmesh.cpp, the longest compiles), which no target reads with.
# make_seeds, which writes seeds through the whole library, is a program of the
# default build, as the command that writes the scenes is.
FZ_LIB       := $(FZ)/libheatvox_parsers.a
FZ_OBJ       := $(patsubst %,$(FZ)/obj/%.o,$(basename $(filter-out src/io/vdb_write.cpp src/io/vdb_packed.cpp src/mesh/vdb_mesh.cpp src/mesh/vdb_volmesh.cpp,\
                  $(filter src/core/% src/io/% src/mesh/%,$(C_SRC) $(CXX_SRC)))))
SEED_TOOL    := $(BUILD)/fuzz/make_seeds

.PHONY: fuzz fuzz-build fuzz-seeds fuzz-clean
fuzz-build:
	+@$(FZ_SUBMAKE) --no-print-directory $(FZ_BINS)

$(FZ_LIB): $(FZ_OBJ)
	@rm -f $@
	ar rcs $@ $^

$(FZ)/fuzz/%.o: tests/fuzz/%.c $(wildcard tests/fuzz/*.h)
	@mkdir -p $(dir $@)
	$(FZ_CC) -Iinclude -D_GNU_SOURCE -std=c11 $(FZ_OPT) $(WARN) $(FZ_SAN) -fsanitize=fuzzer-no-link -c $< -o $@

$(FZ)/fuzz/fuzz_%: $(FZ)/fuzz/fuzz_%.o $(FZ_LIB)
	$(FZ_CXX) -o $@ $^ -fopenmp $(FZ_SAN) -fsanitize=fuzzer $(LDLIBS)

$(SEED_TOOL): tests/fuzz/make_seeds.c $(wildcard tests/fuzz/*.h) $(LIB_A)
	@mkdir -p $(dir $@)
	$(CC) $(CPPFLAGS) $(CFLAGS) $< -o $@ $(LIB_A) $(LDFLAGS) -lstdc++ $(LDLIBS)

# Seeds: `heatvox make-scenes` (the command of the default build: the fuzz
# build instruments the parsers alone), the repository's curve scenes,
# make_seeds (small files in every format, scenes written by assimp's
# exporters, .npy/.exr/.vdb written by the library), and for the assimp target
# the assimp test models under 64 KiB in the formats it reads, each behind the
# byte that picks its extension (tests/fuzz/fuzz_assimp.h).
fuzz-seeds: fuzz-build $(BIN) $(SEED_TOOL)
	+@$(FZ_SUBMAKE) --no-print-directory SEED_BIN=$(CURDIR)/$(BIN) SEED_MAKER=$(CURDIR)/$(SEED_TOOL) \
	  $(FZ)/corpus/.seeded
$(FZ)/corpus/.seeded: $(SEED_MAKER) $(wildcard scenes/curves/*)
	@rm -rf $(FZ)/scenes && mkdir -p $(FZ)/corpus
	$(SEED_BIN) make-scenes -q $(FZ)/scenes
	$(SEED_MAKER) $(FZ)/corpus
	cp $(FZ)/scenes/meshes/*.obj $(FZ)/corpus/obj/
	cp $(FZ)/scenes/levelset/*.vdb $(FZ)/corpus/vdb/
	mkdir -p $(FZ)/corpus/mesh && for t in obj ply stl off; do cp $(FZ)/corpus/$$t/* $(FZ)/corpus/mesh/; done
	cp scenes/curves/*.txt $(FZ)/corpus/curves/
	cp scenes/curves/*.svg $(FZ)/corpus/svg/
	@find $(ASSIMP_MODELS) -type f -size -64k 2>/dev/null | sort | while read -r f; do \
	  case $$(echo "$${f##*.}" | tr A-Z a-z) in gltf) s=0;; glb) s=1;; fbx) s=2;; 3mf) s=3;; \
	    dae) s=4;; x) s=5;; *) continue;; esac; \
	  { printf "\\00$$s"; cat "$$f"; } > "$(FZ)/corpus/assimp/models_$$(echo "$$f" | cksum | cut -d' ' -f1)"; \
	done
	@touch $@

fuzz: fuzz-seeds
	@mkdir -p $(FZ)/logs; rm -f $(FZ)/logs/*.bad
	+@$(MAKE) --no-print-directory -k $(FUZZ_TARGETS:%=fuzz-run-%) || true
	@bad=$$(cd $(FZ)/logs && ls *.bad 2>/dev/null | sed 's/[.]bad$$//' | tr '\n' ' '); \
	echo; if [ -n "$$bad" ]; then echo "fuzz: crashes in: $$bad(logs in $(FZ)/logs/)"; exit 1; fi; \
	echo "fuzz: no crash in $(FUZZ_SECONDS) s per target ($(words $(FUZZ_TARGETS)) targets)"

# The assimp target meets faults inside Debian's libassimp 5.2 itself (null
# pointers, heap overflows and runaway allocations in its glTF and COLLADA
# readers; tests/fuzz/README.md): tests/fuzz/run_assimp.sh runs it on past
# each input whose report reaches libassimp before heatvox's code, moving it
# to $(FZ)/crashes/assimp-lib/ and listing it. Any other fails the run, as for
# every target. Its requests over 2000 MB are refused before they are made:
# such a request otherwise meets the malloc limit's report in one thread and
# the RSS limit's in another, and the two deadlocked (a run that never ended).
# Every run is bounded by timeout(1) besides libFuzzer's own clock.
FZ_ARGS = -rss_limit_mb=2048 -malloc_limit_mb=2048 -timeout=10 -max_len=$(FUZZ_MAX_LEN) \
          -print_final_stats=1 $(FUZZ_FLAGS)

# One target for FUZZ_SECONDS (make -j runs them side by side); a crash
# leaves $(FZ)/logs/NAME.bad.
fuzz-run-%:
	@t=$*; mkdir -p $(FZ)/crashes/$$t; reg=tests/fuzz/regress/$$t; [ -d $$reg ] || reg=; \
	before=$$(ls $(FZ)/crashes/$$t | wc -l); : > $(FZ)/logs/$$t.lib; \
	if [ $$t = assimp ]; then \
	  $(FZ_RUNENV) ASAN_OPTIONS=$(FZ_ASAN):max_allocation_size_mb=2000 \
	    sh tests/fuzz/run_assimp.sh $(FZ)/fuzz/fuzz_$$t $(FUZZ_SECONDS) $(FZ)/crashes/$$t \
	    $(FZ)/crashes/$$t-lib $(FZ)/logs/$$t.log $(FZ_ARGS) $(FZ)/corpus/$$t $$reg > $(FZ)/logs/$$t.lib; \
	else \
	  $(FZ_RUNENV) timeout -k 10 $$(($(FUZZ_SECONDS) + 120)) $(FZ)/fuzz/fuzz_$$t -max_total_time=$(FUZZ_SECONDS) \
	    -artifact_prefix=$(FZ)/crashes/$$t/ $(FZ_ARGS) $(FZ)/corpus/$$t $$reg > $(FZ)/logs/$$t.log 2>&1; \
	fi; rc=$$?; \
	[ $$(ls $(FZ)/crashes/$$t | wc -l) -le $$before ] || rc=1; \
	echo "== fuzz $$t ($(FUZZ_SECONDS) s): $$(grep -E '^#[0-9]+' $(FZ)/logs/$$t.log | tail -n 1)"; \
	[ ! -s $(FZ)/logs/$$t.lib ] || { echo "  set aside, the fault in libassimp:"; cat $(FZ)/logs/$$t.lib; }; \
	if [ $$rc -ne 0 ]; then \
	  touch $(FZ)/logs/$$t.bad; grep -E '^==[0-9]+==ERROR|runtime error|^SUMMARY|Test unit written' \
	    $(FZ)/logs/$$t.log | head -n 5; \
	fi

fuzz-clean:
	rm -rf $(FZ)
# ---- end of fuzz ----

# ---- tsan: ThreadSanitizer over the OpenMP paths, clang 14 ----
# make tsan builds the library, the command and the suites that run threaded
# kernels with clang's -fsanitize=thread into build-tsan/ and runs them with
# libomp's Archer tool, which tells ThreadSanitizer about OpenMP's barriers and
# tasks. ignore_noninstrumented_modules leaves out races inside libraries that
# are not built with it (libomp's own runtime, TBB, OpenVDB, FFTW), as Archer's
# documentation advises; heatvox's code is all instrumented. A race report or a
# failed test fails the target. The GCC-only AVX2/AVX-512 clones are not in
# this build (ThreadSanitizer instruments load-time resolvers); their rows read
# and write the same cells as the baseline rows it checks, but for the AVX2
# row of a binary level in the fused pass, which also writes its other colour
# back unchanged: the pass's slabs keep those cells to one thread at a time
# (mg_rows.c), and the baseline row that this build checks writes them the
# same way.
TS          := build-tsan
# Line tables alone for the C++ files, as in the other sanitized builds.
$(CXX_SRC:%.cpp=$(TS)/obj/%.o): CXXFLAGS += $(CXX_SANLIGHT)
# The longest first: make -j starts them in this order.
TSAN_SUITES ?= check_distance check_mg check_mg_agg check_sdf check_extend check_extend_tiles check_sdf2d check_fftw check_ops
TS_RUNENV   := OMP_TOOL_LIBRARIES=/usr/lib/llvm-14/lib/libarcher.so ARCHER_OPTIONS=verbose=1 \
               TSAN_OPTIONS='ignore_noninstrumented_modules=1 halt_on_error=0 suppressions=$(CURDIR)/tests/tsan.supp' GOMP_SPINCOUNT=1000
.PHONY: tsan
tsan:
	+@$(MAKE) --no-print-directory BUILD=$(TS) HV_PETSC=0 CC=$(FZ_CC) CXX=$(FZ_CXX) OPT='-O1 -g' \
	  SANFLAGS='-fsanitize=thread' DEB_PKGS='$(DEB_PKGS) $(FUZZ_PKGS)' \
	  $(TS)/heatvox $(TSAN_SUITES:%=$(TS)/tests/%)
	@rm -f $(TS)/tests/*.tsan
	+@$(MAKE) --no-print-directory -k $(TSAN_SUITES:%=$(TS)/tests/%.tsan) || true
	@bad=""; for t in $(TSAN_SUITES); do \
	  [ "$$(cat $(TS)/tests/$$t.tsan 2>/dev/null)" = ok ] || bad="$$bad $$t"; \
	done; \
	echo; [ -z "$$bad" ] || { echo "tsan: failing:$$bad"; exit 1; }; \
	echo "tsan: $(words $(TSAN_SUITES)) suites, no race reported"
# One suite under ThreadSanitizer (make -j runs them side by side): "ok" in
# its .tsan file, or what failed, printed with the first reports.
$(TS)/tests/%.tsan:
	@t=$*; log=$(TS)/tests/$$t.log; s0=$$(date +%s); \
	$(TS_RUNENV) HEATVOX_TEST_DATA=$${HEATVOX_TEST_DATA:-../shared/meshes} timeout 1200 $(TS)/tests/$$t > $$log 2>&1; rc=$$?; \
	races=$$(grep -c '^WARNING: ThreadSanitizer' $$log); msg=""; \
	grep -q 'Archer detected OpenMP application' $$log || { rc=1; msg="Archer did not load; "; }; \
	line=$$(grep -E '^[0-9]+%: Checks: ' $$log) || rc=1; \
	echo "== tsan $$t ($$(( $$(date +%s) - s0 )) s): $$line"; \
	if [ $$rc -ne 0 ] || [ $$races -ne 0 ]; then \
	  echo "  $${msg}exit $$rc, $$races race reports (log: $$log)"; \
	  grep -E '^(WARNING: ThreadSanitizer|    #[0-2] )' $$log | head -n 12; \
	  echo failed > $@; \
	else echo ok > $@; fi
# ---- end of tsan ----

-include $(shell find $(BUILD)/obj -name '*.d' 2>/dev/null)
