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
FZ_SAN       := $(SAN_ADDRESS)
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
	$(CC) $(CPPFLAGS) $(CFLAGS) $< -o $@ $(C_PROG_LINK)

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

fuzz: fuzz-seeds ## every parser under libFuzzer for FUZZ_SECONDS
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

fuzz-clean: ## remove the fuzzing build
	rm -rf $(FZ)
# ---- end of fuzz ----
