# make install PREFIX=... (DESTDIR for staging): the library, the public
# headers, the command, the pkg-config file and the Python package.

.PHONY: install
install: all ## the library, headers, command, pkg-config file and Python package under PREFIX
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
