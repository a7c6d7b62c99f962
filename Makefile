# heatvox: make (library + command), make check, make bench, make demo,
# make install PREFIX=..., make sanitize, make format; make help lists every
# target. This file holds what the build is made of (tools, flags, sources,
# names); the rules live in mk/, one file per concern:
#   mk/deps.mk      the Debian packages, installed when missing
#   mk/library.mk   the library (static and shared) and the command
#   mk/tests.mk     make check and make check-long
#   mk/bench.mk     make bench (and its CGAL reference) and make demo
#   mk/install.mk   make install
#   mk/doc.mk       make man and make completion (and their install)
#   mk/mpi.mk       the MPI build and its distributed tests
#   mk/sanitize.mk  make sanitize (ASan, UBSan) and make tsan
#   mk/fuzz.mk      make fuzz (libFuzzer)

# Every target builds in parallel on all CPUs unless -j is given (at the top
# level only: sub-makes share its job server).
ifeq ($(MAKELEVEL)$(filter -j%,$(MAKEFLAGS)),0)
MAKEFLAGS += -j$(shell nproc 2>/dev/null || echo 2)
endif

.DEFAULT_GOAL := all

PREFIX  ?= /usr/local
BUILD   ?= build
CC      ?= cc
CXX     ?= g++
OPT     ?= -O3
SAN     ?=

# The sanitizers' flags, for every sanitized build: ASan with UBSan (make
# sanitize, SAN=1, and make fuzz), ThreadSanitizer (make tsan), and the
# lighter C++ flags all of them use (below).
SAN_ADDRESS  := -fsanitize=address,undefined -fno-sanitize-recover=undefined
SAN_THREAD   := -fsanitize=thread
CXX_SANLIGHT := -g1 -fno-sanitize=alignment,null,object-size,vptr
ifeq ($(SAN),1)
OPT     := -O1 -g -fno-omit-frame-pointer
SANFLAGS := $(SAN_ADDRESS)
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

# MPI and PETSc (optional): where pkg-config finds PETSc (Debian's petsc-dev,
# with OpenMPI, hypre and parallel HDF5), the build links it and gains the
# petsc backend, HDF5 output and the DMDA API; HV_PETSC=0 leaves it out, and
# HV_PETSC=1 insists. `make mpi` installs them and builds with them into
# build-mpi/ (the MPI programs and tests too); `make mpi-check` runs the
# distributed tests under mpirun. The sanitizer and fuzzing builds leave PETSc
# out: MPI's own allocations would read as leaks, and mpi-check covers it.
ifeq ($(origin HV_PETSC),undefined)
HV_PETSC  := $(shell pkg-config --exists PETSc ompi-c hdf5-openmpi 2>/dev/null && echo 1 || echo 0)
endif
ifeq ($(HV_PETSC),1)
CPPFLAGS += -DHV_HAVE_PETSC $(shell pkg-config --cflags PETSc ompi-c hdf5-openmpi 2>/dev/null)
LDLIBS   += $(shell pkg-config --libs PETSc ompi-c hdf5-openmpi 2>/dev/null)
endif


# The library's link line: what a link with libheatvox's objects adds after
# them (the shared library's own, the command's, the tests'); C_PROG_LINK:
# the same for a program the C compiler links against libheatvox.a (the
# MPI programs, the fuzzing seeds' maker), which names the C++ runtime that
# g++ would add. CHECK_LIBS: the test framework's, asked of pkg-config when
# a test links (a fresh machine has it only after make deps).
LIB_LINK    = $(LDFLAGS) $(LDLIBS)
C_PROG_LINK = $(LIB_A) -lstdc++ $(LIB_LINK)
CHECK_LIBS  = $$(pkg-config --libs check)

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


include mk/deps.mk mk/library.mk mk/tests.mk mk/bench.mk mk/install.mk mk/doc.mk mk/blender.mk mk/mpi.mk mk/sanitize.mk mk/fuzz.mk

# make format lays out every C and C++ source by .clang-format; make
# format-check (run by CI) fails, listing the places, when one differs.
FORMAT_SRC = $(sort $(C_SRC) $(CXX_SRC) $(wildcard include/heatvox/*.h src/*/*.h src/*/*/*.h tools/*.c tools/*.h \
               tools/*.cpp tools/bench/*.c tools/bench/*.h tools/bench/*.cpp tests/*.c tests/*.h tests/*.cpp tests/fuzz/*.c tests/fuzz/*.h))
.PHONY: format format-check clean
format: | $(STAMP) ## lay out every C and C++ source by .clang-format
	clang-format -i $(FORMAT_SRC)

format-check: | $(STAMP) ## fail where a source differs from that layout
	@clang-format --dry-run --Werror $(FORMAT_SRC) && echo "format-check: $(words $(FORMAT_SRC)) files as .clang-format lays them out"

clean: ## remove build/, build-san/, build-mpi/ and out/
	rm -rf build build-san build-mpi out


# make help: every target that a line of this file or of mk/ marks with
# "## what it does" after its prerequisites.
.PHONY: help
help: ## this list
	@echo "make targets:"
	@grep -hE '^[a-z][a-z0-9-]*:.*## ' $(MAKEFILE_LIST) | sort -u | \
	  sed -E 's/^([a-z0-9-]+):.*## (.*)$$/\1|\2/' | awk -F'|' '{ printf "  %-16s %s\n", $$1, $$2 }'

-include $(shell find $(BUILD)/obj -name '*.d' 2>/dev/null)
