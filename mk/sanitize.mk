# make sanitize: every suite under ASan and UBSan (SAN=1 into build-san/);
# make tsan: the threaded suites under ThreadSanitizer (clang 14, libomp's
# Archer). The flags are the top Makefile's (SAN_ADDRESS, SAN_THREAD,
# CXX_SANLIGHT).

# The files that only run OpenVDB's own algorithms (VDB_ALGO_SRC) are built
# without instrumentation in the sanitized builds.
ifneq ($(SANFLAGS),)
$(VDB_ALGO_SRC:%.cpp=$(BUILD)/obj/%.o): override SANFLAGS :=
$(VDB_ALGO_SRC:%.cpp=$(BUILD)/obj/%.o): override CXX_SANFLAGS := -g1
# make sanitize takes them from the plain build (VDB_ALGO_FROM) where it has
# them: uninstrumented they are the plain objects but for -O3 and line
# tables, and GCC took 55 s and 74 s to compile them again. Both builds
# preprocess them alike but for _FORTIFY_SOURCE=2 (PETSc's pkg-config flags,
# Debian's hardening, as OpenVDB itself is built), which defines no symbol.
ifneq ($(VDB_ALGO_FROM),)
$(VDB_ALGO_SRC:%.cpp=$(BUILD)/obj/%.o): $(BUILD)/obj/%.o: $(VDB_ALGO_FROM)/obj/%.o
	@mkdir -p $(dir $@)
	cp $< $@
endif
endif

# The plain build's objects of VDB_ALGO_SRC, when both are there: brought up
# to date by this build's rules, then copied into build-san/.
VDB_ALGO_PLAIN := $(VDB_ALGO_SRC:%.cpp=$(BUILD)/obj/%.o)
VDB_ALGO_HAVE  := $(if $(SANFLAGS),,$(if $(filter-out $(wildcard $(VDB_ALGO_PLAIN)),$(VDB_ALGO_PLAIN)),,1))

.PHONY: sanitize
sanitize: ## every suite under ASan and UBSan
	$(if $(VDB_ALGO_HAVE),+$(MAKE) --no-print-directory $(VDB_ALGO_PLAIN))
	$(MAKE) BUILD=build-san SAN=1 HV_PETSC=0 $(if $(VDB_ALGO_HAVE),VDB_ALGO_FROM=$(BUILD)) check \
	  ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
	  LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan.supp


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
tsan: ## the threaded suites under ThreadSanitizer
	+@$(MAKE) --no-print-directory BUILD=$(TS) HV_PETSC=0 CC=$(FZ_CC) CXX=$(FZ_CXX) OPT='-O1 -g' \
	  SANFLAGS='$(SAN_THREAD)' DEB_PKGS='$(DEB_PKGS) $(FUZZ_PKGS)' \
	  $(TS)/heatvox $(TSAN_SUITES:%=$(TS)/tests/%) $(EXAMPLES:$(BUILD)/%=$(TS)/%)
	@rm -f $(TS)/tests/*.tsan
	+@$(MAKE) --no-print-directory -k $(TSAN_SUITES:%=$(TS)/tests/%.tsan) || true
	@bad=""; for t in $(TSAN_SUITES); do \
	  [ "$$(cat $(TS)/tests/$$t.tsan 2>/dev/null)" = ok ] || bad="$$bad $$t"; \
	done; \
	echo; [ -z "$$bad" ] || { echo "tsan: failing:$$bad"; exit 1; }; \
	echo "tsan: $(words $(TSAN_SUITES)) suites, no race reported"
# One suite under ThreadSanitizer (make -j runs them side by side): "ok" in
# its .tsan file, or what failed, printed with the first reports.
$(TS)/tests/%.tsan: ## the threaded suites under ThreadSanitizer
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
