# The two README commands: `make demo` (set up, run the main job) and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/sarmoco demo --out demo-out

test: $(STAMP)
	$(BIN)/python -m pytest -q

BENCHES := bench_mocomp bench_imaging bench_autofocus bench_drivers bench_sim thz_table2 ku_vehicle_table

bench: $(STAMP)
	for b in $(BENCHES); do $(BIN)/python -m bench.$$b || exit 1; done

clean:
	rm -rf $(VENV) demo-out
