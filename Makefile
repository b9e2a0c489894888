# The two commands of the README:
#   make demo   install, then design + export + check the bundled samples end to end
#   make test   install, then run the whole test suite
#
# Set-up installs into .venv. torch comes first, pinned to the CPU build
# (2.13.0) unless TORCH is overridden: a user with a GPU runs
#   make TORCH="torch --index-url https://download.pytorch.org/whl/cu126" test
# or TORCH= to keep a torch already in the venv.

PYTHON ?= python3
VENV   ?= .venv
TORCH  ?= torch==2.13.0
PY      = $(VENV)/bin/python
PIP     = $(PY) -m pip
STAMP   = $(VENV)/.installed

.PHONY: install demo test bench clean tools studio

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	if [ -n "$(TORCH)" ]; then $(PIP) install -q $(TORCH); fi
	$(PIP) install -q -e '.[all,dev]'
	# compile the numba kernels once (cached beside the sources), so the first
	# design or export does not pay for it
	$(PY) -m saucerfab.warmup
	touch $(STAMP)

install: $(STAMP)

# External validators the tests run (not skipped in CI): PrusaSlicer and
# admesh from Debian, the Khronos glTF-Validator from npm.
tools:
	bash .ci/install-tools

demo: install
	$(PY) -m saucerfab.demo --out out/demo

# the studio: a local web page for designers (http://127.0.0.1:8000, workspace ~/saucerfab-studio)
studio: install
	$(PY) -m saucerfab studio

test: install tools
	$(PY) -m pytest -n 2 -q tests

bench: install
	$(PY) benchmarks/run_all.py

clean:
	rm -rf $(VENV) out .pytest_cache
