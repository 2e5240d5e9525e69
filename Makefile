# The two README commands: `make demo` (set up, run the main job) and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test docs bench figures clean install uninstall

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet -e '.[test,docs]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/sarmoco demo --out demo-out

# Three phases (tests/conftest.py REALTIME and EXCLUSIVE say which tests are `realtime`
# and `exclusive`, and why): the rest on three pytest-xdist workers, a module's tests on one
# worker (its fixtures built once; test_install's two in-tree pip builds never overlap;
# a third worker takes up the CPU the others leave while they wait on subprocesses);
# then the realtime tests, a module at a time on two workers (each mostly waits on the
# clock); then the exclusive ones alone, one after the other. The first two phases hand
# the longest modules out first (tests/conftest.py LONGEST_FIRST); the realtime phase
# collects only the modules REALTIME names, the exclusive phase those EXCLUSIVE names.
# Every phase runs; the target fails when any does (pytest's 5, no test collected,
# included). The -m options replace pyproject's, so they name bench and fuzz_long again.
# The suite's processes share the checkout's bytecode (the package's modules, pytest's
# rewritten test modules): where the environment turns writing it off
# (PYTHONDONTWRITEBYTECODE), every `sarmoco` process and every phase's collection would
# compile them again.
NOT_SLOW := not bench and not fuzz_long
test: export PYTHONDONTWRITEBYTECODE :=
test: $(STAMP)
	$(BIN)/python -m pytest -q -p no:cacheprovider -n 3 --dist loadscope --no-loadscope-reorder \
	  --durations=15 \
	  -m "not realtime and $(NOT_SLOW)"; s1=$$?; \
	live=$$($(BIN)/python -c 'from tests.conftest import REALTIME; print(*REALTIME)') || exit 1; \
	alone=$$($(BIN)/python -c 'from tests.conftest import EXCLUSIVE; print(*EXCLUSIVE)') || exit 1; \
	$(BIN)/python -m pytest -q -p no:cacheprovider -n 2 --dist loadfile --no-loadscope-reorder \
	  --durations=15 -m "realtime and not exclusive and $(NOT_SLOW)" $$live; s2=$$?; \
	$(BIN)/python -m pytest -q -p no:cacheprovider --durations=15 \
	  -m "exclusive and $(NOT_SLOW)" $$alone && exit $$(( s1 || s2 ))

# The documentation site (docs/, mkdocs.yml) into site/: the generated reference pages
# first, then a strict build (a broken link or anchor fails). The test suite checks both.
docs: $(STAMP)
	$(BIN)/python docs/gen_reference.py
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

BENCHES := bench_mocomp bench_imaging bench_autofocus bench_drivers bench_sim thz_table2 ku_vehicle_table

bench: $(STAMP)
	for b in $(BENCHES); do $(BIN)/python -m bench.$$b || exit 1; done

# Print the measured figures of docs/measurements (focusing core, range compression,
# GOTCHA, THz Table 2, throughput, the autofocus tables and CPU time, tile PGA, TIMESYNC, replay,
# along-track placement), each by the command named beside it (about 15 minutes on
# 2 cores). The longer runs the pages cite (bench_daemon --live-s 600, bench_drivers,
# bench_tile_pga, bench_survey, the end-to-end tests) are not in it.
figures: $(STAMP)
	$(BIN)/python -m pytest -q -s -p no:cacheprovider tests/processing/imaging/test_imaging_acceptance.py
	$(BIN)/python -m pytest -q -s -p no:cacheprovider tests/processing/test_rangecomp.py -k point_target_peak
	$(BIN)/python -m pytest -q -s -p no:cacheprovider tests/processing/test_gotcha.py
	$(BIN)/python -m bench.thz_table2 --sweep-seeds 6
	$(BIN)/python -m bench.bench_mocomp
	$(BIN)/python -m bench.bench_imaging
	$(BIN)/python -m bench.ku_vehicle_table --scale 0.2
	$(BIN)/python -m bench.ku_vehicle_table --range-orders --scale 0.2
	$(BIN)/python -m bench.ku_vehicle_table --streaming --scale 0.2
	$(BIN)/python -m bench.bench_autofocus --seconds 3
	$(BIN)/python -m pytest -q -s -p no:cacheprovider tests/processing/autofocus/test_gotcha_autofocus.py
	$(BIN)/python -m bench.gotcha_autofocus
	$(BIN)/python -m pytest -q -s -p no:cacheprovider tests/daemon/test_tile_pga.py
	$(BIN)/python -m pytest -q -s -p no:cacheprovider tests/sim/test_emit_mavlink.py -k udp_live
	$(BIN)/python -m bench.bench_daemon --skip-live --profile
	$(BIN)/python -m pytest -q -s -p no:cacheprovider tests/daemon/test_focuser.py -k "along_track or absorbs"

clean:
	rm -rf $(VENV) demo-out site

# Onboard install (docs/integrator.md, "Installing on the payload computer"). DESTDIR stages the tree
# for a package; the virtual environment's scripts are then rewritten to run from PREFIX.
PREFIX ?= /opt/sarmoco
SYSCONFDIR ?= /etc
UNITDIR ?= $(SYSCONFDIR)/systemd/system
SYSCTLDIR ?= $(SYSCONFDIR)/sysctl.d
DOCDIR = $(PREFIX)/share/doc/sarmoco
VENV_ARGS ?=
PIP_ARGS ?=
INSTALL_MARK := share/sarmoco/installed-by-make

install:
	test ! -e '$(DESTDIR)$(PREFIX)' -o -e '$(DESTDIR)$(PREFIX)/$(INSTALL_MARK)' \
	  || { echo '$(DESTDIR)$(PREFIX) exists and was not installed by make install' >&2; exit 1; }
	$(PYTHON) -m venv $(VENV_ARGS) '$(DESTDIR)$(PREFIX)'
	'$(DESTDIR)$(PREFIX)/bin/python' -m pip install --quiet $(PIP_ARGS) .
	if [ -n '$(DESTDIR)' ]; then \
	  grep -rlI --null -F '$(DESTDIR)$(PREFIX)' '$(DESTDIR)$(PREFIX)/bin' '$(DESTDIR)$(PREFIX)/pyvenv.cfg' \
	    | xargs -0 -r sed -i 's|$(DESTDIR)$(PREFIX)|$(PREFIX)|g'; fi
	install -d '$(DESTDIR)$(PREFIX)/share/sarmoco'
	touch '$(DESTDIR)$(PREFIX)/$(INSTALL_MARK)'
	install -D -m 0644 README.md '$(DESTDIR)$(DOCDIR)/README.md'
	install -d '$(DESTDIR)$(DOCDIR)/docs'
	cp -R docs/. '$(DESTDIR)$(DOCDIR)/docs/'
	install -D -m 0644 systemd/sarmoco.toml '$(DESTDIR)$(DOCDIR)/sarmoco.toml.example'
	install -d '$(DESTDIR)$(UNITDIR)'
	sed -e 's|/etc/sarmoco|$(SYSCONFDIR)/sarmoco|g' -e 's|/opt/sarmoco|$(PREFIX)|g' \
	    systemd/sarmoco.service > '$(DESTDIR)$(UNITDIR)/sarmoco.service'
	chmod 0644 '$(DESTDIR)$(UNITDIR)/sarmoco.service'
	install -D -m 0644 systemd/sarmoco-sysctl.conf '$(DESTDIR)$(SYSCTLDIR)/90-sarmoco.conf'
	if [ -e '$(DESTDIR)$(SYSCONFDIR)/sarmoco/sarmoco.toml' ]; then \
	  echo 'kept $(DESTDIR)$(SYSCONFDIR)/sarmoco/sarmoco.toml (the example is in $(DOCDIR))'; \
	else install -D -m 0640 systemd/sarmoco.toml '$(DESTDIR)$(SYSCONFDIR)/sarmoco/sarmoco.toml'; fi
	@echo 'installed; then: sysctl --system; systemctl daemon-reload; systemctl enable --now sarmoco'

# Removes what install put; the configuration only if unchanged from the example, and
# never the recordings (/var/lib/sarmoco).
uninstall:
	test ! -e '$(DESTDIR)$(PREFIX)' -o -e '$(DESTDIR)$(PREFIX)/$(INSTALL_MARK)' \
	  || { echo '$(DESTDIR)$(PREFIX) was not installed by make install: left alone' >&2; exit 1; }
	rm -f '$(DESTDIR)$(UNITDIR)/sarmoco.service' '$(DESTDIR)$(SYSCTLDIR)/90-sarmoco.conf'
	if cmp -s systemd/sarmoco.toml '$(DESTDIR)$(SYSCONFDIR)/sarmoco/sarmoco.toml'; then \
	  rm -f '$(DESTDIR)$(SYSCONFDIR)/sarmoco/sarmoco.toml'; \
	  rmdir '$(DESTDIR)$(SYSCONFDIR)/sarmoco' 2>/dev/null || true; \
	elif [ -e '$(DESTDIR)$(SYSCONFDIR)/sarmoco/sarmoco.toml' ]; then \
	  echo 'kept the edited $(DESTDIR)$(SYSCONFDIR)/sarmoco/sarmoco.toml'; fi
	rm -rf '$(DESTDIR)$(PREFIX)'
