# Every install step lives here, so a fresh clone needs only Python 3.11.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DEMO_DIR ?= runs/demo

.PHONY: install demo test test-cuda bench bench-lean bench-peers docs lint clean

$(STAMP): pyproject.toml Makefile
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test,plot]"
	touch $(STAMP)

install: $(STAMP)

# OpenMP threads that wait by spinning made the demo 20 times slower on a shared machine (a
# laptop with a browser, a login node), and sleeping ones 6.6 times slower on free cores: sphere
# samples the cores at the start and chooses (sphere_cli/runtime.py start_threads).
demo: $(STAMP)
	$(BIN)/sphere run configs/demo.toml -o $(DEMO_DIR) --overwrite
	@echo
	@echo "Output is in $(DEMO_DIR)/:"
	@echo "  $(DEMO_DIR)/trajectory.h5   particle frames (H5MD); open $(DEMO_DIR)/trajectory.xmf in ParaView"
	@echo "  $(DEMO_DIR)/checkpoints/    restart files; continue with: $(BIN)/sphere resume $(DEMO_DIR) --until 0.5"
	@echo "Summary: $(BIN)/sphere inspect $(DEMO_DIR)"

# Passive OpenMP waiting: on a machine shared with other jobs (CI runners), spinning threads made
# 2-thread tests up to 15x slower; a benchmark on dedicated cores keeps the default.
# The suite is mostly Numba compilation, one core each: test files run in up to 4 processes, one
# per core (a file stays in one process, so its fixtures are made once); on 2 cores 668 -> 371 s.
# ParaView (Debian's python3-paraview: pvbatch and its XDMF 3 readers) for the tests that open
# trajectory.xmf as ParaView users do; installed where apt-get can be run as root, and those tests
# are skipped, saying why, where it cannot.
PARAVIEW_STAMP := $(VENV)/.paraview
$(PARAVIEW_STAMP): $(STAMP)
	@if command -v pvbatch >/dev/null; then :; \
	elif command -v apt-get >/dev/null && [ "$$(id -u)" = 0 ]; then \
	  echo "installing ParaView (python3-paraview) for the XDMF reader tests"; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
	    python3-paraview) >/dev/null 2>&1 || echo "ParaView could not be installed: its reader tests will be skipped"; \
	else echo "no apt-get as root: ParaView's reader tests will be skipped"; fi
	touch $@

# Python's bytecode written ahead: where PYTHONDONTWRITEBYTECODE is set (container and CI images),
# each of the suite's ~200 processes (runs, MPI ranks) compiled sphere's modules again: 0.12 s of
# the 0.75 s a `sphere` process took to import itself. Whole files go to the workers in the order
# tests/conftest.py collects them, the longest first (xdist would order them by their count of
# tests), so that no long file runs alone at the end.
test: $(STAMP) $(PARAVIEW_STAMP)
	$(BIN)/python -m compileall -q sphere_cli tests
	OMP_WAIT_POLICY=PASSIVE $(BIN)/python -m pytest -q --durations=10 -n auto --maxprocesses=4 --dist=loadfile --no-loadscope-reorder

# The GPU path with the CUDA extra (numba-cuda and NVIDIA's compiler as wheels, about 0.5 GB, in a
# venv of its own): the GPU tests under numba-cuda's simulator, and every GPU kernel compiled for
# an H200 (sm_90) without a GPU. On a GPU machine, CUDASIM=0 runs the tests on the device.
CUDA_VENV  := .venv-cuda
CUDA_STAMP := $(CUDA_VENV)/.installed
$(CUDA_STAMP): pyproject.toml Makefile
	$(PYTHON) -m venv $(CUDA_VENV)
	$(CUDA_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(CUDA_VENV)/bin/python -m pip install --quiet -e ".[test,cuda]"
	touch $@

test-cuda: $(CUDA_STAMP)
	NUMBA_ENABLE_CUDASIM=$${CUDASIM:-1} $(CUDA_VENV)/bin/python -m pytest -q -p no:randomly tests/unit/test_cuda_dem.py tests/unit/test_cuda_fluids.py

bench: $(STAMP)
	$(BIN)/sphere bench dem
	$(BIN)/sphere bench compile

# sphere against a lean hand-written C kernel of the same scene, side by side (needs gcc)
bench-lean: $(STAMP)
	$(BIN)/python benchmarks/lean_kernel/compare.py 10000 200 11
	$(BIN)/python benchmarks/lean_kernel/compare.py 100000 50 9

# sphere against LIGGGHTS and LAMMPS on the same settled bed, alternating rounds, 1 and 2
# threads / MPI ranks, then against YADE on its bedload example's scene (configs/bedload-yade.toml),
# one core each (benchmarks/peers/). The peers are Debian's packages, installed where apt-get can
# be run as root; a peer that is absent is skipped, saying so. PEER_SIZES to choose the beds (the
# 100 000 bed is settled once, about 15 min of one core, and cached).
PEER_SIZES ?= 10000 100000
bench-peers: $(STAMP)
	@missing=""; for p in liggghts lmp mpirun yade; do command -v $$p >/dev/null || missing=1; done; \
	if [ -n "$$missing" ] && command -v apt-get >/dev/null && [ "$$(id -u)" = 0 ]; then \
	  echo "installing the peers (Debian: liggghts lammps openmpi-bin yade)"; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
	    liggghts lammps openmpi-bin yade) >/dev/null 2>&1 || echo "the peers could not be installed"; fi
	@for n in $(PEER_SIZES); do \
	  if [ $$n -ge 100000 ]; then steps=100; else steps=1000; fi; \
	  $(BIN)/python benchmarks/peers/compare.py $$n $$steps 5 1 2 || exit 1; done
	$(BIN)/python benchmarks/peers/bedload_compare.py 0.5 3

docs: $(STAMP)
	$(BIN)/python -m sphere_cli.config.reference docs/case-reference.md

lint: $(STAMP)
	$(BIN)/ruff check sphere_cli tests benchmarks

clean:
	rm -rf $(VENV) $(CUDA_VENV) runs .pytest_cache
	find . -name __pycache__ -type d -prune -exec rm -rf {} +

# Full verification run (error against run time, stability suite), then the report regenerated.
.PHONY: verify
verify: $(STAMP)
	$(BIN)/sphere verify -o verify-results; status=$$?; \
	$(BIN)/python -m sphere_cli.verify.docs verify-results docs/verification.md && exit $$status
