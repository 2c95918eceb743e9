# fmugen -- the two commands of a fresh machine are `make run` and `make test`.
PYTHON ?= python3
PIP ?= $(PYTHON) -m pip
OUT ?= out

.PHONY: setup run test test-fast bench clean

# install fmugen (editable: the FMU builder compiles c_runtime/ from the checkout) and its test tools
setup:
	$(PIP) install --quiet --disable-pip-version-check -e ".[test]"

# main job: the thesis system (PUMA + six hydraulic chains, one FMU each) co-simulated
# against its monolithic reference; error against run time for every coupling scheme,
# the monolithic FMU and the arm-only torque-driven study (out/thesis/)
run: setup
	$(PYTHON) examples/thesis_system.py --out $(OUT)

# one worker per core (pytest-xdist); a module's tests stay together in one worker (its fixtures built once)
test: setup
	$(PYTHON) -m pytest -q -n auto --dist loadfile

# benchmarks (figures quoted in the issues' closing notes)
bench: setup
	$(PIP) install --quiet --disable-pip-version-check -e ".[bench]"
	$(PYTHON) examples/bench_derivation.py
	$(PYTHON) examples/bench_generated_code.py
	$(PYTHON) examples/bench_stiff_solvers.py

clean:
	rm -rf $(OUT) build *.egg-info .pytest_cache
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
