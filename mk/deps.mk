# The Debian 12 packages heatvox needs, checked with a stamp per list and
# installed when missing (as root; otherwise the command to run is printed).

# Debian 12 packages the build and tests need; installed once when missing.
DEB_PKGS := build-essential pkg-config check libfftw3-dev libopenvdb-dev libboost-dev libopenvdb-tools \
            python3-openvdb libtbb-dev libimath-dev libopenexr-dev libpng-dev \
            ocl-icd-opencl-dev opencl-headers pocl-opencl-icd zlib1g-dev python3-numpy clang-format \
            clang-14 libassimp-dev assimp-testmodels
# Those of CGAL's reference program alone (make bench), checked with a stamp
# of their own by the same rule.
CGAL_PKGS  := libcgal-dev libeigen3-dev
CGAL_STAMP  = $(BUILD)/.deps-cgal-ok
# scikit-fmm, the fast marching reference of the distance rows
# (tools/bench/bench_distance.py, make bench only), the same way.
FMM_PKGS   := python3-scikit-fmm
FMM_STAMP   = $(BUILD)/.deps-fmm-ok
# Open3D, the second reference of the points rows without normals
# (tools/bench/bench_ref_open3d.py), and SciPy, which the orientation's
# alternatives are measured with (tools/bench/orient_alternatives.py):
# make bench only, the same way.
OPEN3D_PKGS := python3-open3d python3-scipy
OPEN3D_STAMP = $(BUILD)/.deps-open3d-ok
# What `pip install .` and `pip wheel .` need of Debian's Python (the wheel
# test of make check, tests/check_pip.py), the same way.
PIP_PKGS   := python3-pip python3-setuptools python3-wheel python3-venv
PIP_STAMP   = $(BUILD)/.deps-pip-ok
# Blender 3.4, which the add-on's tests run in (make check-blender), the same way.
BLENDER_PKGS := blender
BLENDER_STAMP = $(BUILD)/.deps-blender-ok


deps: $(STAMP) ## install the Debian packages the build needs (as root)
$(CGAL_STAMP): DEB_PKGS = $(CGAL_PKGS)
$(FMM_STAMP): DEB_PKGS = $(FMM_PKGS)
$(OPEN3D_STAMP): DEB_PKGS = $(OPEN3D_PKGS)
$(PIP_STAMP): DEB_PKGS = $(PIP_PKGS)
$(BLENDER_STAMP): DEB_PKGS = $(BLENDER_PKGS)
$(STAMP) $(CGAL_STAMP) $(FMM_STAMP) $(OPEN3D_STAMP) $(PIP_STAMP) $(BLENDER_STAMP): mk/deps.mk
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
