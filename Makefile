# Two entry points, each self-installing on a fresh machine:
#   make run    the main job     make test   the test suite
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp

.PHONY: run test bench clean

$(STAMP): setup.py setup.cfg package.xml
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[ros,test,bench]"
	touch $(STAMP)

run: $(STAMP)
	mkdir -p out
	$(VENV)/bin/finger-sim simulate config/paper_flexion.yaml --csv out/paper_flexion.csv --plot out/paper_flexion.png

test: $(STAMP)
	$(VENV)/bin/pytest -q

bench: $(STAMP)
	$(VENV)/bin/finger-sim bench --out docs/

clean:
	rm -rf $(VENV) out build install log
