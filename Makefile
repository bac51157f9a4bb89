# cpg_walker — the two commands of the README are `make demo` and `make test`.
# Both create .venv (Python 3.12, the only Python the ROS 2 Jazzy wheels support) on first use.
SHELL := /bin/bash
VENV  := .venv
PY    := $(VENV)/bin/python
STAMP := $(VENV)/.installed
OUT   ?= results
export MUJOCO_GL ?= egl

.PHONY: demo test test-fast lint bench colcon-check clean venv

venv: $(STAMP)

$(STAMP): requirements.txt setup.py setup.cfg package.xml
	@py=$$(tools/find_python312.sh) || exit 1; \
	if [ ! -x $(PY) ]; then echo "setup: creating $(VENV) with $$py"; "$$py" -m venv $(VENV) || exit 1; fi
	@tools/ensure_egl.sh
	@# pipefail keeps pip's exit status; the filter only hides a local pip index's noise
	set -o pipefail; $(PY) -m pip install --quiet --disable-pip-version-check -r requirements.txt 2>&1 \
	  | { grep -v "is ignored: it is neither" || true; }
	set -o pipefail; $(PY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e . 2>&1 \
	  | { grep -v "is ignored: it is neither" || true; }
	@$(PY) -c "import rclpy, mujoco, numpy, cpg_walker" || { echo "setup: the environment is incomplete (see pip's output above)"; exit 1; }
	@touch $(STAMP)

## demo: set up, then run the main job (the paper's Section II and learning in-process, then the walk
## through the ROS graph for DURATION sim s) into $(OUT)/
DURATION ?= 60
demo: $(STAMP)
	$(VENV)/bin/cpg-walker demo --paper --duration $(DURATION) --out $(OUT)

## test: set up, lint, then the whole test suite (unit + multi-process)
test: $(STAMP)
	$(VENV)/bin/ruff check cpg_walker test
	$(PY) -m pytest -q --durations=25 test

## test-fast: the in-process unit tests only
test-fast: $(STAMP)
	$(PY) -m pytest -q -m "not slow" test

lint: $(STAMP)
	$(VENV)/bin/ruff check cpg_walker test

bench: $(STAMP)
	$(VENV)/bin/cpg-walker bench --out $(OUT)/bench

## colcon-check: build the package with colcon as a ROS install would, into build/colcon
colcon-check: $(STAMP)
	$(PY) tools/colcon_check.py

clean:
	rm -rf build install log results .pytest_cache .ruff_cache *.egg-info
