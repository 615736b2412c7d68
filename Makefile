# Two entry points, each self-installing on a fresh machine:
#   make run    the main job (the paper's run through the node, logged)
#   make test   the test suite
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp

.PHONY: run test test-serial test-halves test-half-ros test-half-rest test-noros bench clean browser

$(STAMP): setup.py setup.cfg package.xml
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[ros,test,bench]"
	$(PY) -m finger_sim.kernel.warm  # numba's cache, so that make run and the first runs do not compile
	touch $(STAMP)

# DDS stays on loopback, in a domain of its own (override: make run ROS_DOMAIN_ID=n).
ROS_DOMAIN_ID ?= 17
ROS_ENV := ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST ROS_DOMAIN_ID=$(ROS_DOMAIN_ID)

# The paper's run through the ROS 2 node, recorded to bags/, then read back from the log.
run: $(STAMP)
	mkdir -p out
	$(ROS_ENV) $(VENV)/bin/finger_node --ros-args -p scene:=paper_flexion -p torque_source:=scene -p realtime_factor:=1.0
	log=$$(ls -t bags/paper_flexion_*.mcap | head -n 1) && \
	$(VENV)/bin/finger-sim info "$$log" && \
	$(VENV)/bin/finger-sim export "$$log" --csv out/paper_flexion.csv --plot out/paper_flexion.png && \
	$(VENV)/bin/finger-sim resim "$$log"
	log=$$(ls -t bags/paper_flexion_*.mcap | head -n 1) && $(VENV)/bin/finger-sim view "$$log" -o out/paper_flexion.html && \
	echo "viewer of this run: file://$(CURDIR)/out/paper_flexion.html (open it in a browser)"

# The numba cache is keyed by the compiled sources: after an edit it is warmed again (well under a
# second when nothing changed), so that the suite's cache test sees what a fresh install leaves.
test: test-halves

# The same tests as one process (about 8-9 min on a quiet 2-core machine).
test-serial: $(STAMP) browser
	$(PY) -m finger_sim.kernel.warm
	$(VENV)/bin/pytest -q

# The default (about 5 min 45 s against 8-9 serially on a quiet 2-core machine): the ROS tests (marker `ros`)
# with the timing tests (marker `timing`, at normal priority) and the rest at once, the rest at nice 19;
# together every test, each once (docs/test_suite.md). One half alone: make test-half-ros.
test-halves: $(STAMP) browser
	$(PY) -m finger_sim.kernel.warm
	@mkdir -p out
	@$(MAKE) --no-print-directory -k -j2 --output-sync=target test-half-ros test-half-rest; status=$$?; \
	  for half in ros rest; do echo "make test-halves, $$half half: $$(tail -n 1 out/test-$$half.txt)"; done; exit $$status

HALF_MARK_ros  := ros or timing
HALF_MARK_rest := not ros and not timing
# The CPU-bound rest yields to the ROS half (its nodes' wall-clock deadlines): it runs on what they leave.
HALF_NICE_rest := nice -n 19
test-half-ros test-half-rest: test-half-%: $(STAMP)
	@mkdir -p out
	@$(HALF_NICE_$*) $(VENV)/bin/pytest -q -m "$(HALF_MARK_$*)" > out/test-$*.txt 2>&1; status=$$?; cat out/test-$*.txt; exit $$status

# The suite on a machine without ROS 2: a venv of its own without the ros extra (no rclpy), where the ROS
# layer (test/ros/, marker `ros`) skips by importorskip and every other test runs (docs/test_suite.md).
NOROS := .venv-noros
$(NOROS)/.installed-stamp: setup.py setup.cfg package.xml
	test -x $(NOROS)/bin/python || python3 -m venv $(NOROS)
	$(NOROS)/bin/python -m pip install --quiet --upgrade pip
	$(NOROS)/bin/python -m pip install --quiet -e ".[test,bench]"
	touch $@

test-noros: $(NOROS)/.installed-stamp browser
	@! $(NOROS)/bin/python -c "import rclpy" 2>/dev/null || { echo "make: rclpy imports in $(NOROS): not a ROS-free venv"; exit 1; }
	$(NOROS)/bin/python -m finger_sim.kernel.warm
	$(NOROS)/bin/pytest -q

# The viewer's browser tests drive Debian's Chromium (test/view/test_view_browser.py): installed here
# when missing and run as root (CI); otherwise they skip, saying why (and fail under CI=true).
browser:
	@test -x /usr/bin/chromium || { [ "$$(id -u)" = 0 ] && apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; } || \
	  echo "make: chromium is not installed (needs root): the browser tests skip"

bench: $(STAMP)
	$(VENV)/bin/finger-sim bench --out docs/

clean:
	rm -rf $(VENV) out build install log
