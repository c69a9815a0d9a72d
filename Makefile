# The README's two commands: `make book` (install, render the demo scene, build the book)
# and `make test` (install, run every test, notebooks included in quick mode).
# Both create ./.venv from scratch on a fresh machine; nothing else needs to be installed.
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: book test install clean

$(STAMP): pyproject.toml
	python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e ".[dev,book,ref,dist]"
	touch $(STAMP)

install: $(STAMP)

book: $(STAMP)
	$(PY) -m gdlearn render scenes/cornell-box.xml --integrator pt --spp 64 --out _build/cornell-box.png
	$(PY) scripts/build_book.py

test: $(STAMP)
	$(PY) -m pytest

clean:
	rm -rf _build .pytest_cache
