# The MPI build (build-mpi/, or MPI_BUILD): Debian's PETSc with OpenMPI,
# hypre and parallel HDF5, the MPI programs and tests, and the distributed
# tests under mpirun.
MPI_BUILD ?= build-mpi
MPI_PKGS  := petsc-dev openmpi-bin python3-h5py
# Ranks 1 to 4 (oversubscribed on small machines); OpenMPI refuses root
# without the two variables.
MPI_RUN := OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1 \
           OMP_NUM_THREADS=1 mpirun --oversubscribe
.PHONY: mpi mpi-deps mpi-check
# Two passes: the packages first, then the build, whose flags come from
# pkg-config when its Makefile is read (a fresh machine has no PETSc before).
# With the packages installed first (make mpi-deps), the default build links
# PETSc too, and `make mpi-check MPI_BUILD=build` reuses it.
mpi-deps: ## install the MPI and PETSc packages
	+@$(MAKE) --no-print-directory BUILD=$(MPI_BUILD) HV_PETSC=1 DEPS_TAG=-mpi DEB_PKGS='$(DEB_PKGS) $(MPI_PKGS)' deps
	@pkg-config --exists PETSc ompi-c hdf5-openmpi || \
	  { echo "heatvox: pkg-config finds no PETSc, OpenMPI or parallel HDF5 after installing $(MPI_PKGS)"; exit 1; }
mpi: mpi-deps ## build with PETSc into $(MPI_BUILD)/
	+@$(MAKE) --no-print-directory BUILD=$(MPI_BUILD) HV_PETSC=1 DEPS_TAG=-mpi DEB_PKGS='$(DEB_PKGS) $(MPI_PKGS)' \
	  all $(MPI_BUILD)/tests/mpi_solve $(MPI_BUILD)/tests/mpi_dmda $(MPI_BUILD)/advect_dmda \
	  $(MPI_BUILD)/bench_mpi
mpi-check: mpi ## the distributed tests on 1 to 4 ranks
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
	$(CC) $(TOOL_CPPFLAGS) $(CPPFLAGS) $(CFLAGS) $< -o $@ $(C_PROG_LINK)
$(MPI_BUILD)/bench_mpi: tools/mpi/bench_mpi.c $(LIB_A) | $(STAMP)
	$(CC) $(TOOL_CPPFLAGS) $(CPPFLAGS) $(CFLAGS) $< -o $@ $(C_PROG_LINK)
$(MPI_BUILD)/tests/mpi_%: tests/mpi/mpi_%.c tests/mpi/mpi_cases.h $(LIB_A) | $(STAMP)
	@mkdir -p $(dir $@)
	$(CC) $(CPPFLAGS) $(CFLAGS) $< -o $@ $(C_PROG_LINK)
