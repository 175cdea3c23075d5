# The two commands of the README:  make demo   and   make test
# Everything is installed into .venv through pyproject.toml; nothing is installed by hand.

PYTHON ?= $(shell command -v python3.11 2>/dev/null || command -v python3)
VENV   ?= .venv
BIN    := $(VENV)/bin
PIP    := $(BIN)/python -m pip --disable-pip-version-check -q
OUT    ?= out

.PHONY: help venv warmup demo test bench lint samples clean

help:
	@echo "make demo    create .venv, install ffd (with the 3D viewer), run the paper's cases into $(OUT)/"
	@echo "make test    create .venv, install ffd with test tools and the optional extras (mpi, openmdao, mphys, viz) and OpenFOAM (apt, as root), run the test suite"
	@echo "make bench   print the speed/memory table (embedding, deform, I/O, volume follow, Jacobian) and the robustness matrix"
	@echo "make warmup  compile the numba kernels once (demo, test and bench do it first; again after the sources change)"
	@echo "make lint    ruff"
	@echo "make samples regenerate samples/ with gmsh (needs the [samples] extra)"

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.stamp-core: pyproject.toml | $(BIN)/python
	$(PIP) install -e .
	@touch $@

$(VENV)/.stamp-test: $(VENV)/.stamp-core
	$(PIP) install -e '.[test]'
	$(PIP) install -e '.[mpi]' || echo "mpi4py/mpich could not be installed: the MPI tests are skipped"
	@touch $@

$(VENV)/.stamp-openmdao: $(VENV)/.stamp-test
	$(PIP) install -e '.[openmdao]' || echo "openmdao could not be installed: its tests and examples are skipped"
	$(PIP) install -e '.[mphys]' || echo "mphys could not be installed: the MPhys tests and example are skipped"
	@touch $@

# OpenFOAM (ESI v1912, Debian's packages) for the tests that compare with checkMesh and run potentialFoam:
# installed with apt-get when running as root on a Debian/Ubuntu machine, else those tests are skipped.
$(VENV)/.stamp-openfoam: | $(BIN)/python
	@if [ -f /usr/share/openfoam/etc/bashrc ]; then echo "OpenFOAM found"; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	  (apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q openfoam openfoam-examples) \
	  || echo "OpenFOAM could not be installed: the OpenFOAM tests are skipped"; \
	else echo "not root or no apt-get: OpenFOAM is not installed, the OpenFOAM tests are skipped"; fi
	@touch $@

$(VENV)/.stamp-viz: $(VENV)/.stamp-core
	$(PIP) install -e '.[viz]' || echo "pyvista could not be installed: pictures use matplotlib only"
	@touch $@

# numba compiles each kernel at its first call (cached on disk in ffdcli/**/__pycache__): compile them
# once here, one line per step, so that no later run pauses (again whenever the sources change)
$(VENV)/.stamp-warm: $(VENV)/.stamp-core $(shell find ffdcli -name '*.py' 2>/dev/null)
	$(BIN)/python -m ffdcli.app.warmup
	@touch $@

warmup: $(VENV)/.stamp-warm

venv: $(VENV)/.stamp-test $(VENV)/.stamp-warm

demo: $(VENV)/.stamp-viz $(VENV)/.stamp-warm
	$(BIN)/python -m ffdcli.app.demo --out $(OUT)

# Two runs: the suite without the real solvers, on every core (pytest-xdist, at most TEST_JOBS workers),
# then the tests that run SU2 and OpenFOAM one after the other (skipped with a reason where absent; each
# solver run takes the cores it finds); each prints its wall time and its slowest tests.
TEST_JOBS ?= 4
test: $(VENV)/.stamp-test $(VENV)/.stamp-openmdao $(VENV)/.stamp-viz $(VENV)/.stamp-openfoam $(VENV)/.stamp-warm
	$(BIN)/python -m pytest -q -m "not solver" -n auto --maxprocesses=$(TEST_JOBS) --durations=15
	$(BIN)/python -m pytest -q -m solver --durations=10

bench: $(VENV)/.stamp-test $(VENV)/.stamp-warm
	$(BIN)/python -m benchmarks

lint: $(VENV)/.stamp-core
	$(PIP) install ruff && $(BIN)/ruff check ffdcli tests benchmarks

samples: $(VENV)/.stamp-core
	$(PIP) install -e '.[samples]'
	$(BIN)/python samples/make_samples.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache
