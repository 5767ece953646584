# Two entry points (see README.md). Each creates .venv with everything rgm needs, cadquery included.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.rgm-installed

.PHONY: demo test bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[occ,test]'
	touch $(STAMP)

## demo: the main job on a bundled example (scan -> .rgm -> IGES/STEP/mesh)
demo: $(STAMP)
	$(BIN)/python -m rgm.demo

## test: the whole test suite
test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 -p no:cacheprovider

clean:
	rm -rf $(VENV) build
