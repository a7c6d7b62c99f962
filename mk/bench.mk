# make bench (tools/bench/bench.sh and the references it runs against) and
# make demo.

# CGAL's Poisson surface reconstruction, the reference of `heatvox bench
# points` (tools/bench/bench_ref_cgal.cpp): a program of its own, built by
# make bench only, since CGAL's headers take a minute to compile. Its Debian
# packages (CGAL_PKGS) are installed, or asked for, by the deps rule. CGAL
# needs -frounding-math for its exact predicates under GCC; NDEBUG drops its
# assertions, as CGAL's release builds do.
REF_CGAL := $(BUILD)/bench_ref_cgal
.PHONY: bench-ref-cgal
bench-ref-cgal: $(REF_CGAL) ## the CGAL reference of bench points
$(REF_CGAL): tools/bench/bench_ref_cgal.cpp $(FLAGS) | $(CGAL_STAMP)
	$(CXX) -std=c++17 $(OPT) $(WARN) -frounding-math -DNDEBUG -DCGAL_EIGEN3_ENABLED \
	  -I/usr/include/eigen3 $< -o $@ -lgmp -lmpfr

.PHONY: bench demo
bench: all $(REF_CGAL) | $(FMM_STAMP) $(OPEN3D_STAMP) ## the benchmarks, one JSON object a line
	@sh tools/bench/bench.sh $(BIN)

demo: all ## the main job on the bundled scenes
	@sh tools/demo.sh $(BIN)
