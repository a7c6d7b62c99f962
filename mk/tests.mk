# make check: the suites of tests/, each a run with its log, exit code and
# time under $(RES), and the summary; make check-long.

# Independent readers the tests compare against (OpenEXR's C++ library).
TEST_HELPERS := $(BUILD)/tests/exr_values
$(BUILD)/tests/exr_values: tests/exr_values.cpp | $(STAMP)
	@mkdir -p $(dir $@)
	$(CXX) -std=c++17 -O2 $(WARN) -I/usr/include/OpenEXR -I/usr/include/Imath $< -o $@ \
	  -lOpenEXR-3_1 -lIex-3_1 -lImath-3_1

# The example programs a user builds against the library (tools/examples/),
# run by the tests (check_extend_tiles: advect_band_cl).
EXAMPLES := $(BUILD)/examples/advect_band_cl
TEST_HELPERS += $(EXAMPLES)
$(BUILD)/examples/%: tools/examples/%.c $(LIB_A) | $(STAMP)
	@mkdir -p $(dir $@)
	$(CC) $(TOOL_CPPFLAGS) $(CFLAGS) $< -o $@ $(C_PROG_LINK)

$(BUILD)/tests/%: $(BUILD)/obj/tests/%.o $(TESTLIB) $(LIB_A)
	@mkdir -p $(dir $@)
	$(CXX) -o $@ $^ $(CHECK_LIBS) $(LIB_LINK)

# check_vdb also tests the reference algorithms of the benchmarks.
$(BUILD)/tests/check_vdb: $(BUILD)/obj/tests/check_vdb.o $(BUILD)/obj/tools/bench/bench_ref_vdb.o $(TESTLIB) $(LIB_A)
	@mkdir -p $(dir $@)
	$(CXX) -o $@ $^ $(CHECK_LIBS) $(LIB_LINK)

# check_points_sample tests the point sampler of the benchmarks.
$(BUILD)/tests/check_points_sample: $(BUILD)/obj/tests/check_points_sample.o \
                                    $(BUILD)/obj/tools/bench/points_sample.o $(TESTLIB) $(LIB_A)
	@mkdir -p $(dir $@)
	$(CXX) -o $@ $^ $(CHECK_LIBS) $(LIB_LINK)

# Each suite sets Check's no-fork mode itself (whatever CK_FORK says): OpenVDB
# (log4cplus/TBB threads) and OpenCL contexts hang forked children
# (docs/METHOD.md, "Testing notes").
# `timeout` stands in for Check's. The OpenCL suites (solver, device fields,
# extension, distance) run a second time as on a device without fp64 (float
# kernels, double correction on the host): the runs named SUITE.fp32; the multigrid suites a second time without their
# AVX-512 kernels (HV_NO512=1, the path of other CPUs): SUITE.no512; the aggregation and distance
# suites a third time without the hand-written AVX2 ones either (HV_NOAVX2=1, the baseline C):
# SUITE.noavx2.
# Runs: each suite, tests/check_kernels.sh (every OpenCL program compiled
# offline as strict OpenCL C 1.2 and 3.0), tests/check_includes.py (the
# include map of src/README.md), tests/check_pip.py (the wheel of `pip wheel
# .` installed into a fresh virtual environment and uninstalled; its
# packages, PIP_PKGS, from mk/deps.mk), the OpenCL ones again as on a device without
# fp64 (NAME.fp32), the multigrid ones and the distance's (its band's sweeps)
# again without AVX-512 (NAME.no512, where the CPU has it) and without AVX2
# (NAME.noavx2, where it has it). make -j runs them
# side by side, the longest first; tests/check_summary.sh prints each log in
# this order, then the totals.
CHECK_SLOW := check_batch check_faults check_mesh_out check_readme check_extend_cl check_sdf_tiles
RUNS_FP32   := $(patsubst %,%.fp32,$(filter check_opencl check_opencl_device check_extend_cl check_distance_cl,$(notdir $(TESTS))))
RUNS_NO512  := $(patsubst %,%.no512,$(filter check_mg check_mg_agg check_distance,$(notdir $(TESTS))))
RUNS_NOAVX2 := $(patsubst %,%.noavx2,$(filter check_mg_agg check_distance,$(notdir $(TESTS))))
# A variant runs only where it takes another path than the plain run: where
# the CPU lacks AVX-512F (or AVX2 with FMA, which the AVX2 rows need) the
# plain run already takes the path that HV_NO512 (HV_NOAVX2) selects. These
# runs are not listed, so not counted; the summary names them in one line.
CPU_FLAGS := $(shell grep -m1 '^flags' /proc/cpuinfo 2>/dev/null)
CHECK_LEFT_OUT :=
ifeq ($(filter avx512f,$(CPU_FLAGS)),)
CHECK_LEFT_OUT += $(if $(RUNS_NO512),$(RUNS_NO512) (no avx512f on this CPU: the plain runs take that path);)
RUNS_NO512 :=
endif
ifneq ($(words $(filter avx2 fma,$(CPU_FLAGS))),2)
CHECK_LEFT_OUT += $(if $(RUNS_NOAVX2),$(RUNS_NOAVX2) (no avx2 with fma on this CPU: the plain runs take that path);)
RUNS_NOAVX2 :=
endif
# make sanitize (SAN=1) leaves out .fp32: each of those suites has a test of
# its own on a float device (HEATVOX_OPENCL_FP64=0: the host's double
# correction, the solve through the host, the distance's host fallback) that
# the plain run takes, and the rest moves other values through the same
# buffers; make check runs them. .no512 and .noavx2 stay where they run:
# their AVX2 and baseline C rows are other memory access paths.
ifeq ($(SAN),1)
CHECK_LEFT_OUT += $(if $(RUNS_FP32),$(RUNS_FP32) (make sanitize: the plain runs take their float paths; make check runs them);)
RUNS_FP32 :=
endif
CHECK_RUNS := $(filter $(CHECK_SLOW),$(notdir $(TESTS))) $(filter-out $(CHECK_SLOW),$(notdir $(TESTS))) \
              check_kernels check_includes check_pip $(RUNS_FP32) $(RUNS_NO512) $(RUNS_NOAVX2)
RES := $(BUILD)/tests/results
# tests/check_readme builds the README's C example and tests/check_api a
# program linked shared and static against an installed copy: make check
# stages `make install` into $(BUILD)/stage first.
STAGE := $(BUILD)/stage
$(STAGE)/.installed: $(LIB_A) $(LIB_SO) $(BIN) $(wildcard include/heatvox/*.h) $(PY_SRC) heatvox.pc.in mk/install.mk
	@mkdir -p $(STAGE)
	+@$(MAKE) --no-print-directory install PREFIX=$(CURDIR)/$(STAGE) DESTDIR= > $(STAGE)/install.log 2>&1 \
	  || { cat $(STAGE)/install.log; exit 1; }
	@touch $@

.PHONY: check
check: all $(TESTS) $(TEST_HELPERS) $(STAGE)/.installed | $(PIP_STAMP) ## build and run every test suite
	@rm -rf $(RES) && mkdir -p $(RES)
	@{ ls -d /tmp/hv_* 2>/dev/null; grep -o ' /tmp/hv_[^ ]*' /proc/mounts; } | sort > $(RES)/tmp.before
	+@$(MAKE) --no-print-directory -k $(CHECK_RUNS:%=$(RES)/%.rc) || true
	@CHECK_LEFT_OUT='$(strip $(CHECK_LEFT_OUT))' sh tests/check_summary.sh $(RES) $(CHECK_RUNS)

# Longer cases that make check shortens (HEATVOX_TEST_LONG=1): the EXR
# volumes of check_batch at every resolution.
.PHONY: check-long
check-long: all $(BUILD)/tests/check_batch $(TEST_HELPERS) ## the cases make check shortens
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
	[ $$run != check_pip ] || t="$(PYTHON) tests/check_pip.py $(BUILD)"; \
	case $$run in *.fp32) fp64=0;; *.no512) no512=1;; *.noavx2) no512=1; noavx2=1;; esac; \
	t0=$$(date +%s%N); \
	HV_NO512=$$no512 HV_NOAVX2=$$noavx2 HEATVOX_OPENCL_FP64=$$fp64 GOMP_SPINCOUNT=$${GOMP_SPINCOUNT:-1000} \
	  POCL_CACHE_DIR=$${POCL_CACHE_DIR:-$(POCL_CACHE)} \
	  HEATVOX_TEST_DATA=$${HEATVOX_TEST_DATA:-../shared/meshes} timeout 900 $$t > $(RES)/$$run.log 2>&1; \
	rc=$$?; ms=$$(( ($$(date +%s%N) - t0) / 1000000 )); \
	echo "$$ms" > $(RES)/$$run.ms; echo $$rc > $@; \
	printf '== %-28s exit %d, %d.%01d s\n' $$run $$rc $$((ms / 1000)) $$((ms % 1000 / 100))
