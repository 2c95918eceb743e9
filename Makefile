# fmugen -- the two commands of a fresh machine are `make run` and `make test`.
PYTHON ?= python3
PIP ?= $(PYTHON) -m pip
OUT ?= out

.PHONY: setup run test test-fast bench clean

# install fmugen (editable: the FMU builder compiles c_runtime/ from the checkout) and its test tools
setup:
	$(PIP) install --quiet --disable-pip-version-check -e ".[test]"

# main job: build the thesis PUMA's ME and CS FMUs, simulate them against a
# high-accuracy reference and report error against run time
run: setup
	$(PYTHON) examples/puma_fmu_vs_reference.py --out $(OUT)

test: setup
	$(PYTHON) -m pytest -q

# benchmarks (figures quoted in the issues' closing notes)
bench: setup
	$(PIP) install --quiet --disable-pip-version-check -e ".[bench]"
	$(PYTHON) examples/bench_derivation.py
	$(PYTHON) examples/bench_generated_code.py
	$(PYTHON) examples/bench_stiff_solvers.py

clean:
	rm -rf $(OUT) build *.egg-info .pytest_cache
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
