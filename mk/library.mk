# The library (libheatvox.a, libheatvox.so) and the command (build/heatvox):
# the kernels embedded, every object, the archives and the links.
.PHONY: all
all: $(LIB_A) $(LIB_SO) $(BIN) ## the library and the command
.SECONDARY:

$(BUILD)/gen/kernels.c: $(CL_SRC) mk/library.mk | $(STAMP)
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
	  -o $@ $(OBJ) $(LIB_LINK)

$(LIB_SO): $(LIB_SOV)
	ln -sf $(notdir $<) $(BUILD)/libheatvox.so.$(SOMAJOR)
	ln -sf $(notdir $<) $@

$(BIN): $(BUILD)/obj/tools/heatvox.o $(patsubst %.c,$(BUILD)/obj/%.o,$(filter-out tools/heatvox.c,$(wildcard tools/*.c tools/bench/*.c))) $(TOOL_CXX_OBJ) $(LIB_A)
	$(CXX) -o $@ $^ $(LIB_LINK)
